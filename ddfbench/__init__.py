"""ddfbench: a benchmark of shape representations (mesh, DDF, neural SDF, grid SDF, GAN-SDF)."""

import os

__version__ = "0.1.0"

# Hydra configs live in conf/ at the top level of the repository (next to this package).
CONF_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "conf")
