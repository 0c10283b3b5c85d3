"""3D Gaussian Splatting in pure JAX: parameters, projection, tiles, rasterisation.

Static shapes throughout (jit-friendly): a scene is a fixed-capacity set of Gaussians
with an `active` mask; `render.render` ties projection (EWA splatting), spherical-harmonic
colour, tile intersection and front-to-back alpha blending together. Conventions follow
`renerf_jax.cameras` (OpenGL camera-to-world poses, pixel centres at integer + 0.5) so a
Gaussian and a NeRF render of the same camera agree on where a 3D point lands.
"""
