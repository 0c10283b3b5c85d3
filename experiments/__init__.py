"""Experiment scripts (tables, ablations, plots): python -m experiments.<name>."""
