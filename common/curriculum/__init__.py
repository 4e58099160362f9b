"""The ``curriculum`` application, above the simulator-free core of :mod:`common`: the YAML schema,
the stage runner and its run directory, policy files, transfer evidence, sweeps on Ray, the
benchmarks, the comparison reports and the CLI. The tiers and the learning, plotting and cluster
libraries are imported here, never by the core."""
