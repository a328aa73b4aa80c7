"""Studies: design comparison (compare), the paper's geometry (geometry) and every benchmark
behind `irring bench` and `python -m irring.studies.serial_link`; each returns plain figures."""
