"""Plots of the paper's figures and tables from run files (see higbench.figures.registry)."""
