"""Studies of the method: the scenes they run on, the engine that draws and scores their samples into CSV rows,
the tables generated from those rows, and the small sweeps shared by benchmarks and tests."""
