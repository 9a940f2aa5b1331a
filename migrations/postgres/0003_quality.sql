-- Each generated result's quality reports (a JSON array, one per sample: foot skating, foot
-- flight, jitter and the rest, as anymo_models::quality::QualityReport writes them). Results
-- stored before this column existed have none.
ALTER TABLE generations ADD COLUMN quality TEXT;
