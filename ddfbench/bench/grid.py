"""Section 5, grid SDF build: the level-set build (ddfbench.truth.levelset.levelset_sdf_grid: exact narrow
band + fast sweeping + component signs) against brute force (the oracle's signed distance at every
node), per resolution: time, and the largest error in the narrow band (|exact| <= 2 grid steps), in a
wider shell (<= 8 steps) and overall.

Each build runs once (a build is seconds to minutes; nothing lazy is left to warm after the first
resolution). Brute force is run in full up to `exact_full_max`; above, it runs on `exact_sample`
random nodes, its time is that sample's time scaled by n^3 / sample (brute force costs the same per
node), and the errors are over that sample (the row note says so). At the largest fully-run
resolution the sample's per-node rate is measured too, as a check of that scaling.
Sizes: shape, resolutions, exact_full_max, exact_sample.
"""

from __future__ import annotations

import numpy as np

from ddfbench.bench.context import DOMAIN, Context
from ddfbench.bench.results import SectionResult, compare
from ddfbench.bench.timing import once
from ddfbench.truth import levelset


def errors(grid_values: np.ndarray, exact: np.ndarray, h: float) -> dict:
    """Largest |grid - exact| in the band (<= 2h), the shell (<= 8h) and overall; sign disagreements.
    grid_values and exact: SDF values at the same nodes (any shape, unit-cube units); h: the grid spacing."""
    err = np.abs(grid_values - exact)
    out = {"nodes_compared": int(exact.size), "max_err_all": float(err.max()), "mean_err_all": float(err.mean()),
           "sign_flips": int((np.sign(grid_values) != np.sign(exact)).sum())}
    for key, width in (("max_err_band", 2 * h), ("max_err_shell8", 8 * h)):
        sel = np.abs(exact) <= width
        out[key] = float(err[sel].max()) if sel.any() else 0.0
        out[f"{key}_nodes"] = int(sel.sum())
    return out


def sample_nodes(n: int, m: int, seed: int = 0) -> np.ndarray:
    """m distinct random node indices (m, 3) of an n^3 grid."""
    flat = np.random.default_rng(seed).choice(n**3, size=min(m, n**3), replace=False)
    return np.stack(np.unravel_index(flat, (n, n, n)), -1)


def run(ctx: Context) -> SectionResult:
    s = ctx.sizes
    oracle = ctx.oracle(s["shape"])
    result = SectionResult()
    full_max, m = int(s["exact_full_max"]), int(s["exact_sample"])
    for n in (int(r) for r in s["resolutions"]):
        h = 2 * DOMAIN / (n - 1)
        (grid_values, info), ls_t = once(lambda: levelset.levelset_sdf_grid(oracle, n, DOMAIN))
        detail = {"levelset": ls_t.as_dict(), "levelset_info": info}
        if n <= full_max:
            exact, exact_t = once(lambda: levelset.exact_sdf_grid(oracle, n, DOMAIN))
            exact_s, how = exact_t.median_s, "brute force run in full"
            detail["errors"] = errors(grid_values, exact, h)
        nodes = sample_nodes(n, m)
        exact_sample, sample_t = once(lambda: oracle.signed_distance(levelset.node_points(nodes, n, DOMAIN)))
        detail["exact_sample"] = {**sample_t.as_dict(), "nodes": len(nodes),
                                  "seconds_per_node": sample_t.median_s / len(nodes)}
        if n > full_max:
            exact_s = sample_t.median_s * n**3 / len(nodes)
            how = f"brute force timed on {len(nodes)} random nodes, scaled by n^3; errors on those nodes"
            detail["errors"] = errors(grid_values[tuple(nodes.T)], exact_sample, h)
        else:
            detail["exact_full_seconds_per_node"] = exact_s / n**3
        e = detail["errors"]
        detail["exact_seconds"] = exact_s
        result.details[f"n={n}"] = detail
        result.rows.append(compare(
            "grid", f"grid SDF build {n}^3, level set: seconds", ls_t.median_s, "s", "brute-force exact grid seconds",
            exact_s, inverse=True, device="cpu", threads=ctx.threads,
            note=f"ratio = speedup; {how}; max |err| band {e['max_err_band']:.2g}, shell(8h) "
                 f"{e['max_err_shell8']:.2g}, all {e['max_err_all']:.2g} (h = {h:.2g}); sign flips {e['sign_flips']}"))
    return result
