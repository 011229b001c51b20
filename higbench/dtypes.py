"""The dtype names a config may give (``dtype``, ``optimizer.precision``) and their torch dtypes."""

import torch

DTYPES = {"float32": torch.float32, "float64": torch.float64}
