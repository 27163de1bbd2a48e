"""Ground truth: shapes and their catalog, the exact ray oracle with its Embree, open3d and Warp backends,
and the exact signed-distance grid built by a level set. Imports only ddfbench.core.
"""
