"""Deriving what a photo capture lacks: cameras, masks, a surface and its UV atlas.

- `sfm`: camera poses by structure from motion (COLMAP via pycolmap), normalised for dpi;
- `masks`: foreground masks (colour keying, or GrabCut from a sphere / sparse-point prior, refined
  in rounds from the visual hull the views agree on);
- `geometry`: a voxel signed-distance field carved from masks, marching cubes, pymeshlab clean-up;
- `uv`: UV atlas (xatlas) and baking of functions of position into textures;
- `stages`: the stage functions the workflow's rules `poses`, `masks`, `geometry`, `uv` run, and
  `complete_capture`, which fills a capture's derived inputs in for the later stages;
- `accuracy`: pose, mask and surface errors against ground truth (tests, benchmarks).
"""
