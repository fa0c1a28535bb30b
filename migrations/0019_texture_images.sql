-- Step 19: the instrument camera's texture images that an X-Rite QC `.xlsx` export carries
-- with a measurement (the `Texture Images` sheet), kept with the scan imported from it.
--
-- `texture_images` holds each PNG once, by its SHA-256 (content-addressed): importing the same
-- file again, or two measurements sharing an image, stores no second copy. `scan_textures`
-- gives a scan its images in the file's order, each with the label the file writes beside it
-- (a 15° geometry such as '15as-45', or '15d') and the cell it was anchored in.
CREATE TABLE texture_images (
    sha256 TEXT    PRIMARY KEY CHECK (length(sha256) = 64),
    png    BLOB    NOT NULL CHECK (substr(png, 1, 8) = X'89504E470D0A1A0A')
);

CREATE TABLE scan_textures (
    scan_id  INTEGER NOT NULL REFERENCES scans (id),
    position INTEGER NOT NULL CHECK (position >= 0),
    label    TEXT    NOT NULL,
    anchor   TEXT    NOT NULL,
    sha256   TEXT    NOT NULL REFERENCES texture_images (sha256),
    PRIMARY KEY (scan_id, position)
);
