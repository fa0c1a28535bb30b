-- Step 4: samples, by their unique name (e.g. "T.Freesia pink"). A sample may be scanned many
-- times; each scan points here.
CREATE TABLE samples (
    id            INTEGER PRIMARY KEY,
    name          TEXT    NOT NULL UNIQUE CHECK (length(name) > 0),
    created_at_ms BIGINT  NOT NULL
);
