"""The rasteriser of commit 7346aa4 (tiles.py, rasterize.py, render.py) and its loss.py
(the SSIM blur differentiated through slices), as they were before issue 51's rewrite,
verbatim but for their imports, for benchmarks that time the old and the new training
step in the same run (benchmarks/bench_raster.py)."""
