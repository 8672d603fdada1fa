"""Other labs' files in and out: ``rig import`` through a column map (map, read, importer)
and ``rig export`` to CSV, Parquet, MATLAB and XLSX (exporter)."""
