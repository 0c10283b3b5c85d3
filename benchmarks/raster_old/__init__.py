"""The rasteriser of commit 7346aa4 (rasterize.py, render.py) and its loss (loss.py: the
SSIM blur differentiated through slices), as they were before issue 51's rewrite, for
benchmarks that time the old and the new training step in the same run
(benchmarks/bench_raster.py). What issue 51 left unchanged (the tile lists, sanitise,
the SSIM's masked statistics) is imported from the package, not copied."""
