"""ddfbench: a benchmark of shape representations (mesh, DDF, neural SDF, grid SDF, GAN-SDF)."""

__version__ = "0.1.0"
