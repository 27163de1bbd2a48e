"""ddfbench: a benchmark of shape representations (mesh, DDF, neural SDF, grid SDF, GAN-SDF)."""

# The major version is the suite version (conf/suite/v1.yaml): what the benchmark measures; CHANGELOG.md says at
# which code commit each tier's reports were made.
__version__ = "1.7.1"
