"""`dpi make-envmaps`, `dpi train-prior`, `dpi sample-prior`: console commands of the prior."""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from functools import partial

from dpi.capture import PRIORS
from dpi.io.settings import field_default, field_help
from dpi.light.tonecurve import ENCODINGS
from dpi.prior.train import DEFAULT_MODEL, LR_SCHEDULES, PriorJobConfig, TrainConfig
from dpi.render.backend import set_threads


def cmd_make_envmaps(args: argparse.Namespace) -> None:
    """Generate a procedural env-map dataset."""
    from dpi.prior.procedural import make_envmap_dataset
    from dpi.render import backend

    backend.mitsuba(threads=args.threads)
    if args.packed:
        from dpi.light.tonecurve import family_encoding
        from dpi.prior.procedural import make_packed_dataset

        manifest = make_packed_dataset(args.family, args.count, args.height, args.out,
                                       family_encoding(args.family, args.encoding), seed=args.seed)
    else:
        manifest = make_envmap_dataset(args.family, args.count, args.height, args.out, seed=args.seed)
    print(json.dumps(manifest, indent=2))


def cmd_pack_envmaps(args: argparse.Namespace) -> None:
    """Pack a folder of env maps into one .npz in prior space (to train elsewhere)."""
    from dpi.light.tonecurve import family_encoding
    from dpi.prior.data import EnvmapDataset

    data = EnvmapDataset.from_folder(args.data, args.height, args.family, family_encoding(args.family, args.encoding))
    data.save(args.out)
    print(f"{args.out}: {len(data)} maps of {args.height} x {2 * args.height}, {args.encoding} encoding")


def cmd_panorama_set(args: argparse.Namespace) -> None:
    """Build a packed training (or held-out) set from a folder of real panoramas, checked against the manifest."""
    from dpi.light.tonecurve import family_encoding
    from dpi.prior.panoramas import build_panorama_set

    data = build_panorama_set(args.data, args.family, args.height, family_encoding(args.family, args.encoding),
                              args.split)
    data.save(args.out)
    print(f"{args.out}: {len(data)} {args.family} panoramas ({args.split}) of {args.height} x {2 * args.height}")


def cmd_train_prior(args: argparse.Namespace) -> None:
    """Train (or resume training) a prior on a folder of env maps."""
    from dpi.io.settings import SettingsError
    from dpi.prior.train import TrainConfig, export_model, train

    set_threads(args.threads)
    try:
        config = TrainConfig(model=args.model, steps=args.steps, batch_size=args.batch_size, lr=args.lr,
                             warmup_steps=args.warmup_steps, lr_schedule=args.lr_schedule, init=args.init,
                             ema_decay=args.ema_decay, max_minutes=args.max_minutes, sample_every=args.sample_every,
                             seed=args.seed, encoding=args.encoding, clip_fraction=args.clip_fraction,
                             real_data=args.real_data, real_fraction=args.real_fraction)
    except SettingsError as exc:
        raise SystemExit(f"train-prior: {exc}") from None
    train(config, args.family, args.data, args.out)
    if args.export:
        export_model(args.out, args.export)


def cmd_train_baseline(name: str, network_cls: type, training_cls: type, train_fn: Callable, export_fn: Callable,
                       args: argparse.Namespace) -> None:
    """Train (or resume training) a learned baseline (`train-reni`, `train-gan`) on the diffusion priors' training
    set, then export it when asked."""
    from dataclasses import fields

    from dpi.io.settings import SettingsError, settings_from_dict
    from dpi.prior.baselines import training_set

    set_threads(args.threads)
    try:
        network = settings_from_dict(network_cls, {f.name: getattr(args, f.name) for f in fields(network_cls)})
        config = settings_from_dict(training_cls, {f.name: getattr(args, f.name) for f in fields(training_cls)})
    except SettingsError as exc:
        raise SystemExit(f"{name}: {exc}") from None
    height = getattr(network, "height", None) or args.height
    maps = training_set(args.family, height, args.data, args.real_data, config.real_fraction)
    print(f"{name}: {len(maps)} {args.family} maps of {maps.height} x {2 * maps.height}", flush=True)
    train_fn(network, config, maps, args.out)
    if args.export:
        export_fn(args.out, args.export)


def cmd_sample_prior(args: argparse.Namespace) -> None:
    """Draw unconditional samples from a prior checkpoint and write them as EXR (+ a PNG grid)."""
    from dpi.prior.sample import sample_to_files

    set_threads(args.threads)
    sample_to_files(args.checkpoint, args.out, count=args.count, steps=args.steps, seed=args.seed,
                    random_roll=not args.no_roll, device=args.device)


FLOAT_OPTIONS = ("lr", "lr_latent", "kl_weight", "real_fraction", "max_minutes", "r1_weight", "ema_decay")
"""the learned baselines' training options that are numbers, not integers"""


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the prior's subcommands to the main `dpi` parser."""
    p = subparsers.add_parser("make-envmaps", help="generate a procedural env-map dataset (EXR)")
    p.add_argument("--family", choices=PRIORS, required=True)
    p.add_argument("--count", type=int, default=field_default(PriorJobConfig, "count"))
    p.add_argument("--height", type=int, default=field_default(PriorJobConfig, "data_height"), help="map height H (width 2H)")
    p.add_argument("--out", required=True, help="output folder (EXR files), or .npz file with --packed")
    p.add_argument("--packed", action="store_true", help="write one packed .npz in prior space (to train elsewhere)")
    p.add_argument("--encoding", choices=ENCODINGS, default=field_default(TrainConfig, "encoding"), help="encoding of a packed dataset")
    p.add_argument("--seed", type=int, default=field_default(TrainConfig, "seed"))
    p.add_argument("--threads", type=int, default=1)
    p.set_defaults(fn=cmd_make_envmaps)

    p = subparsers.add_parser("pack-envmaps", help="pack a folder of env maps into one .npz in prior space")
    p.add_argument("--family", choices=PRIORS, required=True)
    p.add_argument("--data", required=True, help="folder of .exr/.hdr/.png/.jpg panoramas")
    p.add_argument("--height", type=int, default=32, help="map height H of the prior (width 2H)")
    p.add_argument("--encoding", choices=ENCODINGS, default=field_default(TrainConfig, "encoding"))
    p.add_argument("--out", required=True, help="output .npz")
    p.set_defaults(fn=cmd_pack_envmaps)

    p = subparsers.add_parser("panorama-set", help="pack a folder of real HDR panoramas (checked against the "
                              "manifest dpi/data/panoramas.csv) into a training or held-out set")
    p.add_argument("--family", choices=PRIORS, required=True)
    p.add_argument("--data", required=True, help="folder of .hdr/.exr panoramas (the manifest's and your own)")
    p.add_argument("--split", choices=("train", "held_out"), default="train",
                   help="the manifest's split; files it does not name are training data")
    p.add_argument("--height", type=int, default=32, help="map height H of the prior (width 2H)")
    p.add_argument("--encoding", choices=ENCODINGS, default=field_default(TrainConfig, "encoding"))
    p.add_argument("--out", required=True, help="output .npz")
    p.set_defaults(fn=cmd_panorama_set)

    p = subparsers.add_parser("train-prior", help="train a diffusion prior on a folder of env maps")
    p.add_argument("--family", choices=PRIORS, required=True)
    p.add_argument("--data", required=True, help="folder of .exr/.hdr/.png/.jpg panoramas, or a packed .npz")
    p.add_argument("--encoding", choices=ENCODINGS, default=field_default(TrainConfig, "encoding"),
                   help="log: log radiance around the median (holds a sun); paper: the family's tone curve")
    p.add_argument("--out", required=True, help="checkpoint path (resumed when it exists)")
    p.add_argument("--export", default=None, help="then write the shippable model (EMA weights, fp16) here")
    p.add_argument("--model", default=DEFAULT_MODEL, help="name in dpi.prior.unet.SMALL_CONFIGS")
    p.add_argument("--init", default=None,
                   help="start a new run from this prior checkpoint's weights (the same network; its map size may differ)")
    p.add_argument("--lr-schedule", choices=LR_SCHEDULES, default=field_default(TrainConfig, "lr_schedule"),
                   help="cosine: decay the learning rate to 0 at --steps")
    for name, kind, text in (("steps", int, None), ("batch_size", int, None), ("lr", float, None),
                             ("warmup_steps", int, "linear learning-rate warm-up"), ("ema_decay", float, None),
                             ("max_minutes", float, "stop (with a checkpoint) after this wall time"),
                             ("sample_every", int, None),
                             ("seed", int, None),
                             ("clip_fraction", float, "share of each batch clipped like 8-bit panoramas"),
                             ("real_data", str, "real panoramas mixed in: a folder or a set from `dpi panorama-set`"),
                             ("real_fraction", float, "share of each batch drawn from --real-data")):
        p.add_argument(f"--{name.replace('_', '-')}", type=kind, default=field_default(TrainConfig, name), help=text)
    p.add_argument("--threads", type=int, default=1)
    p.set_defaults(fn=cmd_train_prior)

    from dataclasses import fields

    from dpi.prior.gan import GANNetwork, GANTraining, export_gan, train_gan
    from dpi.prior.reni import RENINetwork, RENITraining, export_reni, train_reni

    for name, help_text, network_cls, training_cls, train_fn, export_fn in (
            ("train-reni", "train a RENI decoder (the `reni` method's prior)", RENINetwork, RENITraining, train_reni,
             export_reni),
            ("train-gan", "train the GAN baseline's generator (the `gan` method's prior)", GANNetwork, GANTraining,
             train_gan, export_gan)):
        p = subparsers.add_parser(name, help=f"{help_text} on the diffusion priors' training set: procedural maps "
                                  "with real panoramas mixed in")
        p.add_argument("--family", choices=PRIORS, required=True)
        p.add_argument("--data", required=True, help="procedural maps: a folder or a packed .npz (`dpi make-envmaps`)")
        p.add_argument("--real-data", default=None, help="real panoramas: a folder or a set from `dpi panorama-set`")
        if "height" not in {f.name for f in fields(network_cls)}:  # the maps' size, when the network has none
            p.add_argument("--height", type=int, default=32, help="map height H the maps are read at (width 2H)")
        p.add_argument("--out", required=True, help="checkpoint path (resumed when it exists)")
        p.add_argument("--export", default=None, help="then write the shippable network (no training state) here")
        for cls in (network_cls, training_cls):
            for f in fields(cls):
                kind = float if f.name in FLOAT_OPTIONS else int
                p.add_argument(f"--{f.name.replace('_', '-')}", type=kind, default=field_default(cls, f.name),
                               help=field_help(cls, f.name))
        p.add_argument("--threads", type=int, default=2)
        p.set_defaults(fn=partial(cmd_train_baseline, name, network_cls, training_cls, train_fn, export_fn))

    p = subparsers.add_parser("sample-prior", help="draw unconditional env maps from a prior checkpoint")
    p.add_argument("--checkpoint", required=True)
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--count", type=int, default=8)
    p.add_argument("--steps", type=int, default=100, help="respaced number of reverse steps")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-roll", action="store_true", help="disable the per-step random roll (Eq. 15)")
    p.add_argument("--device", default="cpu")
    p.add_argument("--threads", type=int, default=1)
    p.set_defaults(fn=cmd_sample_prior)


def main(argv: list[str] | None = None) -> None:
    """Stand-alone entry point: `python -m dpi.prior.commands <command> ...`."""
    parser = argparse.ArgumentParser(prog="dpi-prior", description=__doc__)
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    args.fn(args)


if __name__ == "__main__":
    main()
