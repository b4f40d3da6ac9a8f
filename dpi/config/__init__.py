"""A run's configuration: the config files resolved into one mapping, checked against the schema and the
settings classes (validation), and read as every stage's typed settings and paths (pipeline)."""
