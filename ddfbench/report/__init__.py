"""Turn run records into tables (md, csv, tex), plots and claims; and the analysis tools that re-measure
saved runs (reevaluate, zero_level, edge_error)."""
