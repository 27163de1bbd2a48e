"""Problem sizes per section: "default" (the committed run: the bunny, the issue's sizes; about 3 min
on 2 idle CPU cores, 16 min when a sweep shares them) and "small" (tiny shapes and networks, seconds:
for tests and quick checks). The training section runs every learned family (ddfbench.models.learned_families)."""

from __future__ import annotations

SIZES: dict[str, dict[str, dict]] = {
    "default": {
        "sampling": {"shape": "bunny", "face_mode": "per_face", "s_fc": 1, "s_dr": 5, "s_p": 10,
                     "bare_rays": 1_000_000},
        "oracle": {"shape": "bunny", "primary_px": 384, "incoherent_rays": 500_000},
        "ddf": {"shape": "bunny", "px": 320, "model": {}},
        "tracing": {"shape": "bunny", "neural_px": 48, "grid_px": 96, "fit_seconds": 30.0, "n_samples": 200_000,
                    "grid_resolution": 128, "neural": {}},
        "grid": {"shape": "bunny", "resolutions": [64, 128, 256], "exact_full_max": 64, "exact_sample": 300_000},
        "metrics": {"shape": "bunny", "points": [10_000, 100_000, 1_000_000], "repeats_max_points": 100_000},
        "training": {"shape": "bunny", "steps": 20, "overrides": {}},
        "end_to_end": {"runs": [{"name": "default run", "args": []},
                                {"name": "smoke sweep", "args": ["+experiment=smoke"]}]},
        # GPU scale (run by default on CUDA only): 1M primary and 1M incoherent rays, 1k..16M sweep
        "race": {"shape": "bunny", "px": 1024, "incoherent_rays": 1 << 20,
                 "sweep": [1000, 4000, 16_000, 64_000, 256_000, 1 << 20, 1 << 22, 1 << 24], "embree_max": 1 << 24,
                 "fit_seconds": 25.0, "fit_steps": 0, "prepared": None, "ray_seed": 1, "n_samples": 200_000,
                 "grid_resolution": 128, "chunk": 1 << 21, "compile": True, "sdf_compile": True, "sdf_eager": True, "sdf_loops": True,
                 "embree": True, "main": True, "capacities": True,
                 "capacity_levels": None, "lods": [1000, 4000, 16000], "model": {}, "neural": {}},
        "field_cost": {"points": 8192, "chunks": [8, 16, 32, 64, 128, 256, 1024, 4096], "gemm": 2048,
                       "sdf_preset": "neural_sdf_tuned", "gan_preset": "gan_sdf_tuned"},
        "gan_train": {"batch": 1024},  # the thesis preset's batch
        # the bunny's 56,172 triangles decimated to 1k-16k and subdivided x4, x16, x64 (to 3.6M)
        "crossover": {"shape": "bunny", "counts": [1000, 4000, 16000, 56172, 224688, 898752, 3595008], "px": 256,
                      "incoherent_rays": 1 << 18, "models": ["ddf_tuned", "ddf_line_grid_tuned"], "prepared": None},
    },
    "small": {
        "sampling": {"shape": "sphere", "face_mode": "total", "s_fc": 1, "s_dr": 2, "s_p": 2, "bare_rays": 20_000},
        "oracle": {"shape": "sphere", "primary_px": 32, "incoherent_rays": 4096},
        "ddf": {"shape": "sphere", "px": 16, "model": {"width": 32, "depth": 2, "eval_batch": 4096}},
        "tracing": {"shape": "sphere", "neural_px": 12, "grid_px": 16, "fit_seconds": 0.5, "n_samples": 5000,
                    "grid_resolution": 16, "neural": {"width": 16, "depth": 2, "batch": 512}},
        "grid": {"shape": "sphere", "resolutions": [12, 20], "exact_full_max": 12, "exact_sample": 2000},
        "metrics": {"shape": "sphere", "points": [1000, 3000], "repeats_max_points": 1000},
        "training": {"shape": "sphere", "steps": 3,
                     "overrides": {"ddf": {"width": 32, "depth": 2, "batch": 256},
                                   "neural_sdf": {"width": 16, "depth": 2, "batch": 256},
                                   "gan_sdf": {"batch": 128}}},
        "end_to_end": {"runs": [{"name": "tiny single run",
                                 "args": ["shape=cube", "model=mesh", "eval=smoke", "scene=none", "sampling=random",
                                          "sampling.n_samples=2000"]}]},
        "race": {"shape": "sphere", "px": 12, "incoherent_rays": 300, "sweep": [100, 400], "embree_max": 100,
                 "fit_seconds": 0.3, "fit_steps": 0, "prepared": None, "ray_seed": 1, "n_samples": 3000,
                 "grid_resolution": 16, "chunk": 128, "compile": False, "sdf_compile": False, "sdf_eager": True,
                 "sdf_loops": True, "embree": True, "main": True, "capacities": True, "capacity_levels": None,
                 "lods": [300],
                 "model": {"batch": 256}, "neural": {"width": 16, "depth": 2, "batch": 256}},
        "field_cost": {"points": 256, "chunks": [64, 256], "gemm": 128,
                       "sdf_preset": "neural_sdf_tuned", "gan_preset": "gan_sdf_tuned"},
        "gan_train": {"batch": 16},
        "crossover": {"shape": "sphere", "counts": [500, 2000, 20480], "px": 16, "incoherent_rays": 512,
                      "models": ["ddf_tuned"], "prepared": None},
    },
}
