# Diffusion prior (issue 3): procedural env-map datasets, then DDPM training on them.
# Optional config, all keys with defaults (per-family overrides under prior.<family>):
#   prior:
#     count: 3000          # maps per procedural dataset
#     data_height: 64      # generated map height H (maps are H x 2H; indoor ray casting costs ~H^2)
#     seed: 0
#     model: small_32x64   # name in dpi.prior.unet.SMALL_CONFIGS
#     steps: 20000
#     batch_size: 8
#     lr: 0.0003
#     ema_decay: 0.995
#     max_minutes: null    # stop training after this wall time (the checkpoint resumes next run)
#     sample_every: 1000
#     device: cpu
#     threads: 1
#     indoor: {count: 1200, data_height: 32}
PRIOR = config.get("prior", {})
PRIOR_DEFAULTS = {"count": 3000, "data_height": 64, "seed": 0, "model": "small_32x64", "steps": 20000,
                  "batch_size": 8, "lr": 3e-4, "ema_decay": 0.995, "max_minutes": None, "sample_every": 1000, "device": "cpu",
                  "threads": 1}
PRIOR_FAMILY_DEFAULTS = {"indoor": {"count": 1200, "data_height": 32}}


PRIOR_TYPES = {"max_minutes": float}  # keys whose default (None) does not tell the type


def prior_setting(family, key):
    """prior.<family>.<key>, else prior.<key>, else the family default, else the global default (typed)."""
    default = PRIOR_FAMILY_DEFAULTS.get(family, {}).get(key, PRIOR_DEFAULTS[key])
    value = PRIOR.get(family, {}).get(key, PRIOR.get(key, default))
    kind = PRIOR_TYPES.get(key, type(default))
    return None if value is None or value == "null" else kind(value)


rule envmap_dataset:
    output:
        directory(f"{RESULTS}/prior_data/{{family}}"),
    params:
        maps=lambda w: prior_setting(w.family, "count"),
        height=lambda w: prior_setting(w.family, "data_height"),
        seed=lambda w: prior_setting(w.family, "seed"),
    wildcard_constraints:
        family="outdoor|indoor",
    threads: 1
    log:
        f"{RESULTS}/prior/{{family}}/logs/envmap_dataset.log",
    script:
        "../workflow_scripts/make_envmap_dataset.py"


rule train_prior:
    input:
        f"{RESULTS}/prior_data/{{family}}",
    output:
        f"{RESULTS}/prior/{{family}}/model.pt",
    params:
        checkpoint=lambda w: f"{RESULTS}/prior/{w.family}/train/checkpoint.pt",
        settings=lambda w: {k: prior_setting(w.family, k) for k in
                            ("model", "steps", "batch_size", "lr", "ema_decay", "max_minutes", "sample_every", "device", "seed")},
    wildcard_constraints:
        family="outdoor|indoor",
    threads: lambda w: prior_setting(w.family, "threads")
    log:
        f"{RESULTS}/prior/{{family}}/logs/train_prior.log",
    benchmark:
        f"{RESULTS}/prior/{{family}}/benchmarks/train_prior.tsv"
    script:
        "../workflow_scripts/train_prior.py"
