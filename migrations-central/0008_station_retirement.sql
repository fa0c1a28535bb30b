-- Central step 8: a station's old store retired, so that a copy of it (a bench moved to a new
-- PC) can take the station id over (src/sync/retire.rs, `brdfd sync --retire-old ARCHIVE_ID`).
--
-- Retiring moves every central row of the station to a new station id, the archive, kept as
-- it was (its own stations row, cursor and incarnations); the station id itself then starts
-- afresh for the store that retired it. The archive's row says where it came from:
-- * `stations.retired_from`: the station id the archive's rows were forwarded under;
-- * `stations.retired_at`: when it was retired.
-- No store forwards under an archive id (it is refused, with the reason).
ALTER TABLE stations ADD COLUMN retired_from TEXT;
ALTER TABLE stations ADD COLUMN retired_at TIMESTAMPTZ;
