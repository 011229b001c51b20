"""Hydra sweeper ``hydra/sweeper=joblist``: a multirun over an explicit list of jobs."""
