"""Directed distance field (DDF): an MLP phi(x, theta) -> distance along theta, plus visibility.

Modules: network (DDFNet, the checked config), line_grid (the optional line encoding), rays (box entry, normals), fit (labels and training),
mesh (extraction), family (the Representation: queries and the artifact).

A ray (origin o, unit direction d) is answered with one network query at the
point where it enters the field box [-domain, domain]^3: t = t_entry + phi(x_e, d),
a hit when the visibility says so and the hit lies inside the box. Normals come
from one backward pass, n = grad_x phi (paper Eqs. 3 and 7), signed so n.d < 0.
The mesh (mesh_field "signed", the default) is the zero set of a signed field built from whole
lines: through a grid node x and along direction theta the network, queried once at the line's box
entry (as for a camera ray), says where the line first crosses the surface; x lies before that
crossing (s >= 0, outside or occluded) or past it (s < 0). Near the surface the lines facing it agree,
and a truncated mean over them (as in depth-map fusion) is the value (see line_vote); marching cubes
runs on a coarse-to-fine narrow band (ddfbench.evaluate.extract.banded_grid) whose fine nodes query only the
mesh_keep lines their coarse parent found nearest the surface. mesh_field "udf" is the paper's
UDF(x) = min over K directions of phi(x, theta_k), taken only over directions whose visibility says
hit (paper Eq. 5), meshed as a thin shell.

cfg keys (conf/model/ddf.yaml documents each):
  network   width, depth, activation (relu | softplus), weight_norm, dropout
  inputs    direction ("vector" unit vector | "angles" polar+azimuth as in the paper),
            param ("point": x as given | "ray": x split into the foot point of its line
            and the coordinate s0 = x.d along it; the net then predicts where along the
            line the hit lies, which is constant along a ray), pos_freqs, dir_freqs
            (positional-encoding octaves; 0 = raw input), line_grid_points (K > 0: the MLP also reads
            a multiresolution feature grid at K points along the line's chord through the box;
            line_grid_levels, _features, _base, _finest, _log2_size shape it: see line_grid)
  heads     visibility ("head": a logit trained with cross entropy | "clamp": no head,
            hit where the clamped distance stays below clamp_hit_ratio * delta, as in the paper)
  loss      loss ("l1" | "clamp" | "clamp_misses", with delta: ddfbench.models.ddf.fit.clamp_loss), vis_weight, entry_share (share of each batch drawn
            from line_entry_labels of up to MAX_ENTRY_LINES sample lines, visibility only, half hits
            and half misses; none unless the samples carry line_hit and it has both), batch, lr, weight_decay,
            lr_schedule / lr_final_ratio / lr_warmup (ddfbench.fit.train.Schedule), grad_clip
  mesh      mesh_field ("signed" | "udf"); signed: mesh_directions (K on the coarsest lattice),
            mesh_keep (lines per finer node), mesh_band (truncation, unit-cube units), mesh_rank
            (order statistic of |s| used as the distance bound away from the surface), mesh_coarse
            (stride of the first lattice), mesh_lipschitz (narrow-band bound);
            udf: udf_directions (K), udf_rank (1 = the min; r = the r-th smallest, robust to
            a spurious hit), udf_level_steps (level in grid steps), udf_coarse,
            udf_lipschitz (narrow band, see ddfbench.evaluate.extract.banded_grid), udf_project
            (move shell vertices onto the predicted surface along -normal)
  storage   storage_dtype (float32 | float16 state dict), eval_batch
"""

from ddfbench.models.ddf.family import DDF
from ddfbench.models.ddf.fit import line_entry_labels
from ddfbench.models.ddf.mesh import fibonacci_directions, line_vote
from ddfbench.models.ddf.rays import unit_normals

FAMILY = DDF
__all__ = ["DDF", "FAMILY", "fibonacci_directions", "line_entry_labels", "line_vote", "unit_normals"]
