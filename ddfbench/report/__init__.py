"""Turn run records into tables (md, csv, tex) and plots."""
