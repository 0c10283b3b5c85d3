"""The rasteriser of commit 7346aa4 (tiles.py, rasterize.py, render.py as they were before
issue 51's rewrite), kept verbatim but for its imports, for benchmarks that time the old
and the new rasteriser in the same run (benchmarks/bench_raster.py)."""
