"""Studies: design comparison (compare), the paper's geometry (geometry) and every benchmark
behind `irring bench`, `python -m irring.studies.serial_link` and `python -m
irring.studies.speed`; each returns plain figures."""
