"""The bottom stage: what every other stage shares and nothing in ddfbench is imported by.

errors (the one-line InputError and its helpers), geometry (the field box, grid nodes, camera rays),
clock (the synchronized timer), heap (releasing freed memory), plugins (the registry of families and
samplers read from conf/), representation (the Representation interface every family implements).
"""
