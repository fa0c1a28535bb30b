-- Step 17: the store's lineage, so that a copy of a store cannot pass for the store it was
-- copied from (src/sync/lineage.rs, ARCHITECTURE.md "Several stations, one lab").
--
-- A copy of the file carries the same `sync_identity.uid` and the same outbox, so nothing in
-- the file tells the original from the copy. What differs is what happens next: each time a
-- store is opened for writing it begins a new incarnation, a random id appended here with the
-- highest outbox entry the store held at that moment (`born_after`). Two copies opened after
-- the copy was made append two different incarnations after the same last one; the central
-- database remembers the last incarnation that forwarded for the station and how far its
-- effects reached (`stations.incarnation`, `stations.horizon`), and accepts a store only if that
-- incarnation is in the store's lineage and the store's next incarnation began at or after the
-- horizon. The copy that comes second is refused before any of its rows is written.
--
-- * `seq` orders the incarnations; the last row is the incarnation now writing (or, for a
--   stopped store, the last that wrote).
-- * The first row stands for the store's life before this step.
CREATE TABLE sync_lineage (
    seq           INTEGER PRIMARY KEY AUTOINCREMENT,
    incarnation   TEXT    NOT NULL UNIQUE CHECK (length(incarnation) = 32),
    born_after    BIGINT  NOT NULL,
    started_at_ms BIGINT  NOT NULL
);
INSERT INTO sync_lineage (incarnation, born_after, started_at_ms)
VALUES (lower(hex(randomblob(16))),
        COALESCE((SELECT seq FROM sqlite_sequence WHERE name = 'sync_outbox'), 0),
        CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
