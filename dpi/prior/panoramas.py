"""Real HDR panoramas in the prior's diet: the shipped manifest and the training set built from a folder.

The manifest (dpi/data/panoramas.csv) names each real panorama the project uses: its family (the prior it
feeds: studios feed the indoor one), its kind (`sun`, `sky`: outdoor without a visible sun, `indoor`,
`studio`), its split
(`train`, or `held_out`: never trained on, the realism benchmark's), its licence, the public repository,
path and commit it was taken from, its original page and its SHA-256. The maps themselves do not ship:
`dpi panorama-set` rebuilds a packed set from a folder holding them. A file the manifest names must match
its checksum; any other panorama in the folder (a user's own Laval or Poly Haven collection) is taken as
training data of the family asked for.
"""

from __future__ import annotations

import csv
import hashlib
import unicodedata
from dataclasses import dataclass, fields
from pathlib import Path

from dpi.light.tonecurve import Encoding
from dpi.prior.data import EnvmapDataset, list_panoramas

MANIFEST = Path(__file__).resolve().parents[1] / "data" / "panoramas.csv"
SPLITS = ("train", "held_out")
KINDS = ("sun", "sky", "indoor", "studio")


@dataclass(frozen=True)
class Panorama:
    """One manifest row."""

    name: str
    family: str
    kind: str
    split: str
    licence: str
    source: str
    path: str
    commit: str
    original: str
    sha256: str


def read_manifest(path: str | Path = MANIFEST) -> dict[str, Panorama]:
    """Manifest rows by file name (NFC-normalised); a missing column or an unknown split is an error naming
    the file and the row."""
    with open(path, newline="") as handle:
        rows = list(csv.DictReader(handle))
    names = [f.name for f in fields(Panorama)]
    entries = {}
    for i, row in enumerate(rows, start=2):
        missing = [n for n in names if not row.get(n)]
        if missing:
            raise ValueError(f"{path}: line {i}: missing {', '.join(missing)}")
        if row["split"] not in SPLITS:
            raise ValueError(f"{path}: line {i}: split must be one of {', '.join(SPLITS)}, got {row['split']!r}")
        if row["kind"] not in KINDS:
            raise ValueError(f"{path}: line {i}: kind must be one of {', '.join(KINDS)}, got {row['kind']!r}")
        entries[unicodedata.normalize("NFC", row["name"])] = Panorama(**{n: row[n] for n in names})
    return entries


def sha256_of(path: str | Path) -> str:
    """Hex SHA-256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def panorama_files(folder: str | Path, family: str, split: str,
                   manifest: dict[str, Panorama] | None = None) -> list[Path]:
    """The folder's panoramas of `family` in `split`. A file the manifest names takes its family and split and
    must match its checksum (else ValueError naming the file); any other file is the user's own, of `family`,
    in the train split."""
    if split not in SPLITS:
        raise ValueError(f"split must be one of {', '.join(SPLITS)}, got {split!r}")
    manifest = read_manifest() if manifest is None else manifest
    chosen = []
    for path in list_panoramas(folder):
        entry = manifest.get(unicodedata.normalize("NFC", path.name))
        if entry is None:
            if split == "train":
                chosen.append(path)
            continue
        if sha256_of(path) != entry.sha256:
            raise ValueError(f"{path}: SHA-256 differs from the manifest's ({entry.sha256[:12]}...): "
                             f"not the file taken from {entry.source} {entry.path}")
        if entry.family == family and entry.split == split:
            chosen.append(path)
    if not chosen:
        raise FileNotFoundError(f"{folder}: no {family} panoramas in the {split} split")
    return chosen


def build_panorama_set(folder: str | Path, family: str, height: int, encoding: Encoding, split: str,
                       manifest: dict[str, Panorama] | None = None) -> EnvmapDataset:
    """The folder's `family` panoramas of `split`, area-resampled to `height`, normalised and encoded as the
    prior's training maps are (dpi.prior.data)."""
    files = panorama_files(folder, family, split, manifest)
    return EnvmapDataset.from_folder(folder, height, family, encoding, files=files)
