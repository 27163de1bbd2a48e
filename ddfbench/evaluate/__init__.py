"""Measuring a field or a mesh: the geometry metrics and their registry, extraction of a field's level set
as a mesh (marching cubes), and sphere tracing of a signed-distance field. Families use extraction and
tracing to answer the Representation interface, so this stage sits below the models.
"""
