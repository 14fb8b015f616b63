"""Many runs: the paper's comparison (`canalnav compare`), studies on Dask with their report
(`canalnav sweep`), seeded encounters (`fuzz`) and the soak (`bench soak`)."""
