-- Central step 5: each station's lineage, so that a copy of a station's store is refused
-- before any of its rows is written (src/sync/lineage.rs, station migration 0017).
--
-- * `stations.incarnation`: the last incarnation of the store that forwarded for the station
--   (NULL until a brdfd with lineage forwards).
-- * `stations.horizon`: the highest outbox entry of the station's store whose effects may be in
--   the central rows (the snapshots the rows were read from reach that far); at least `cursor`.
-- * `stations.heartbeat_at`: when that incarnation last forwarded or, idle, looked at its
--   cursor (every second). Another incarnation is refused while this is recent: two live
--   copies never take turns.
-- * `station_incarnations`: every incarnation that forwarded, when it was first and last seen.
-- * `station_refusals`: every store refused for a station (a copy, an older backup), with the
--   reason, for the lab's administrator; the station shows the same in `brdfd status`.
ALTER TABLE stations ADD COLUMN incarnation TEXT;
ALTER TABLE stations ADD COLUMN horizon BIGINT NOT NULL DEFAULT 0;
ALTER TABLE stations ADD COLUMN heartbeat_at TIMESTAMPTZ;
UPDATE stations SET horizon = cursor;

CREATE TABLE station_incarnations (
    station     TEXT        NOT NULL REFERENCES stations (station),
    incarnation TEXT        NOT NULL,
    first_seen  TIMESTAMPTZ NOT NULL DEFAULT now(),
    last_seen   TIMESTAMPTZ NOT NULL DEFAULT now(),
    PRIMARY KEY (station, incarnation)
);

CREATE TABLE station_refusals (
    id          BIGSERIAL   PRIMARY KEY,
    station     TEXT        NOT NULL,
    store_uid   TEXT        NOT NULL,
    incarnation TEXT        NOT NULL,
    host        TEXT,
    reason      TEXT        NOT NULL,
    at          TIMESTAMPTZ NOT NULL DEFAULT now()
);
