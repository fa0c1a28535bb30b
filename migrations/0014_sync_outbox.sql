-- Step 14: the sync outbox — every committed insert or update of a forwarded row, in commit
-- order, for the forwarder that copies a station's store to the lab's central PostgreSQL
-- database (src/sync/, ARCHITECTURE.md "Several stations, one lab").
--
-- Triggers fill it, so every writer path is captured without the verbs knowing: the row is
-- queued by the same transaction that writes it, and SQLite's single writer makes `seq` the
-- commit order. An entry names the table and the row's local id; the forwarder reads the row as
-- it is when it forwards (so a scan that changed state twice is sent once, in its last state),
-- upserts it in PostgreSQL keyed by (station, local id), and moves the station's cursor in the
-- same PostgreSQL transaction. The cursor lives in the central database, so reading this table
-- is all a forwarder does to a store it does not own. The daemon deletes entries at or below
-- the cursor the central database acknowledged.
--
-- * `seq` is AUTOINCREMENT: SQLite then never hands out a number twice, even after the entries
--   with the highest numbers are deleted, so a new entry can never fall at or below a cursor.
-- * `at_ms` is the local commit time (ms since the Unix epoch, UTC), for the lag figures.
-- * Evaluations are queued once per fit run, by the summary row ('evaluation_summaries', keyed
--   by fit_run_id): the summary and the 14 ΔE00 values are written in one transaction.
-- * Nothing deletes forwarded rows locally; a deletion is not forwarded.
-- * `sync_identity.uid` tells this store apart from any other claiming the same station id.
CREATE TABLE sync_outbox (
    seq        INTEGER PRIMARY KEY AUTOINCREMENT,
    table_name TEXT    NOT NULL,
    row_id     BIGINT  NOT NULL,
    at_ms      BIGINT  NOT NULL
);

CREATE TABLE sync_identity (
    only_row INTEGER PRIMARY KEY CHECK (only_row = 1),
    uid      TEXT    NOT NULL CHECK (length(uid) = 32)
);
INSERT INTO sync_identity (only_row, uid) VALUES (1, lower(hex(randomblob(16))));

CREATE TRIGGER sync_instruments_insert AFTER INSERT ON instruments BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('instruments', NEW.id,
        CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
CREATE TRIGGER sync_instruments_update AFTER UPDATE ON instruments BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('instruments', NEW.id,
        CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
CREATE TRIGGER sync_samples_insert AFTER INSERT ON samples BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('samples', NEW.id,
        CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
CREATE TRIGGER sync_samples_update AFTER UPDATE ON samples BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('samples', NEW.id,
        CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
CREATE TRIGGER sync_reference_sets_insert AFTER INSERT ON reference_sets BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('reference_sets', NEW.id,
        CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
CREATE TRIGGER sync_reference_sets_update AFTER UPDATE ON reference_sets BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('reference_sets', NEW.id,
        CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
CREATE TRIGGER sync_reference_readings_insert AFTER INSERT ON reference_readings BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('reference_readings', NEW.id,
        CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
CREATE TRIGGER sync_reference_readings_update AFTER UPDATE ON reference_readings BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('reference_readings', NEW.id,
        CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
CREATE TRIGGER sync_scans_insert AFTER INSERT ON scans BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('scans', NEW.id,
        CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
CREATE TRIGGER sync_scans_update AFTER UPDATE ON scans BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('scans', NEW.id,
        CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
CREATE TRIGGER sync_readings_insert AFTER INSERT ON readings BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('readings', NEW.id,
        CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
CREATE TRIGGER sync_readings_update AFTER UPDATE ON readings BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('readings', NEW.id,
        CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
CREATE TRIGGER sync_processed_insert AFTER INSERT ON processed BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('processed', NEW.id,
        CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
CREATE TRIGGER sync_processed_update AFTER UPDATE ON processed BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('processed', NEW.id,
        CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
CREATE TRIGGER sync_fit_runs_insert AFTER INSERT ON fit_runs BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('fit_runs', NEW.id,
        CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
CREATE TRIGGER sync_fit_runs_update AFTER UPDATE ON fit_runs BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('fit_runs', NEW.id,
        CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
CREATE TRIGGER sync_evaluation_summaries_insert AFTER INSERT ON evaluation_summaries BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('evaluation_summaries',
        NEW.fit_run_id, CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
CREATE TRIGGER sync_evaluation_summaries_update AFTER UPDATE ON evaluation_summaries BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('evaluation_summaries',
        NEW.fit_run_id, CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;
CREATE TRIGGER sync_evaluations_update AFTER UPDATE ON evaluations BEGIN
    INSERT INTO sync_outbox (table_name, row_id, at_ms) VALUES ('evaluation_summaries',
        NEW.fit_run_id, CAST((julianday('now') - 2440587.5) * 86400000.0 AS INTEGER));
END;

-- What the store held before this step is queued once, parents before children, so a station
-- upgraded in the middle of its life forwards everything it ever measured.
INSERT INTO sync_outbox (table_name, row_id, at_ms)
    SELECT 'instruments', id, last_seen_ms FROM instruments ORDER BY id;
INSERT INTO sync_outbox (table_name, row_id, at_ms)
    SELECT 'samples', id, created_at_ms FROM samples ORDER BY id;
INSERT INTO sync_outbox (table_name, row_id, at_ms)
    SELECT 'reference_sets', id, taken_at_ms FROM reference_sets ORDER BY id;
INSERT INTO sync_outbox (table_name, row_id, at_ms)
    SELECT 'reference_readings', id, taken_at_ms FROM reference_readings ORDER BY id;
INSERT INTO sync_outbox (table_name, row_id, at_ms)
    SELECT 'scans', id, requested_at_ms FROM scans ORDER BY id;
INSERT INTO sync_outbox (table_name, row_id, at_ms)
    SELECT 'readings', id, received_at_ms FROM readings ORDER BY id;
INSERT INTO sync_outbox (table_name, row_id, at_ms)
    SELECT 'processed', id, created_at_ms FROM processed ORDER BY id;
INSERT INTO sync_outbox (table_name, row_id, at_ms)
    SELECT 'fit_runs', id, queued_at_ms FROM fit_runs ORDER BY id;
INSERT INTO sync_outbox (table_name, row_id, at_ms)
    SELECT 'evaluation_summaries', e.fit_run_id, COALESCE(f.finished_at_ms, f.queued_at_ms)
    FROM evaluation_summaries e JOIN fit_runs f ON f.id = e.fit_run_id ORDER BY e.fit_run_id;
