"""Jobs: one unit of work from files to files (a wrap), and the TOML job-file format."""
