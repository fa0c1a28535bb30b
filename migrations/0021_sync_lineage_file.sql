-- Step 21: which file each incarnation of the store wrote, and whether it ended cleanly, so that
-- a copy of a store taken while it was open (`VACUUM INTO`, `sqlite3 .backup`, `cp` of a live
-- file) is known as such by what it holds (src/sync/lineage.rs, ARCHITECTURE.md "Several
-- stations, one lab").
--
-- * `file_id`: the store file's identity (device and inode) when the incarnation began; NULL
--   for incarnations before this step.
-- * `closed_at_ms`: when the incarnation closed the store cleanly (NULL while it runs, and for
--   one that crashed).
-- * `copied`: 1 when the incarnation began in another file than the one before it while that
--   one had not been closed: the file is a copy of a store that was open, whose original may be
--   going on. Such an incarnation does not take a station over from the original by itself.
ALTER TABLE sync_lineage ADD COLUMN file_id TEXT;
ALTER TABLE sync_lineage ADD COLUMN closed_at_ms BIGINT;
ALTER TABLE sync_lineage ADD COLUMN copied INTEGER NOT NULL DEFAULT 0 CHECK (copied IN (0, 1));
