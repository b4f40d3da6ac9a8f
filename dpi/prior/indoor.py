"""Procedural indoor environment maps: a random room path-traced by Mitsuba into an equirect map.

A room is a closed box (walls, floor, ceiling with random diffuse albedo) with windows (area
emitters whose radiance texture is a patch of a procedural outdoor map, so they show sky above
ground), ceiling panel lights, sometimes a spot light, and furniture blocks. Mitsuba has no spherical sensor,
so the map is rendered by handing one jittered ray per texel and sample, leaving a point inside
the room in the texel's direction, to the `path` integrator's `sample` (dpi's +Y-up convention).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import median_filter

from dpi import backend
from dpi.envmap import directions_from_angles

WALL_COLOURS = np.array([[0.85, 0.83, 0.78], [0.7, 0.75, 0.8], [0.8, 0.7, 0.55], [0.6, 0.7, 0.6], [0.9, 0.9, 0.9]])
FLOOR_COLOURS = np.array([[0.45, 0.3, 0.18], [0.3, 0.3, 0.3], [0.6, 0.55, 0.45], [0.2, 0.15, 0.1]])
WARM_WHITE = np.array([1.0, 0.85, 0.65])
MAX_DEPTH = 3
SPP = 32
ROOM_SPACING = 50.0  # metres between packed rooms (rooms are at most 9 m wide)


def rectangle(mi, centre: np.ndarray, normal: np.ndarray, half_u: float, half_v: float, up: np.ndarray) -> dict:
    """Mitsuba rectangle centred at `centre`, facing `normal`, with half extents along (normal x up, up)."""
    to_world = mi.ScalarTransform4f().look_at(origin=centre.tolist(), target=(centre + normal).tolist(), up=up.tolist())
    return {"type": "rectangle", "to_world": to_world @ mi.ScalarTransform4f().scale([half_u, half_v, 1.0])}


def diffuse(colour: np.ndarray) -> dict:
    """Two-sided Lambertian BSDF of an RGB albedo."""
    return {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": colour.tolist()}}}


def window_view(rng: np.random.Generator) -> np.ndarray:
    """(h, w, 3) outdoor radiance seen through a window: the horizon band of a procedural outdoor map."""
    from dpi.prior.outdoor import outdoor_envmap

    env = outdoor_envmap(16, rng)
    start = rng.integers(0, 32 - 8)
    return np.ascontiguousarray(env[4:12, start:start + 8])


def room_scene(rng: np.random.Generator) -> tuple[dict, np.ndarray]:
    """(Mitsuba scene dict, camera point) of a random furnished room spanning [0, W] x [0, Hr] x [0, D]."""
    mi = backend.mitsuba()
    size = np.array([rng.uniform(3, 9), rng.uniform(2.4, 4.0), rng.uniform(3, 9)])
    x_axis, y_axis, z_axis = np.eye(3)
    wall = diffuse(WALL_COLOURS[rng.integers(len(WALL_COLOURS))] * rng.uniform(0.5, 1.0))
    scene: dict = {"type": "scene", "integrator": {"type": "path", "max_depth": MAX_DEPTH}}
    centre = size / 2
    faces = [  # (normal pointing into the room, centre, half extents along the rectangle's (u, v), up)
        (y_axis, centre * [1, 0, 1], (size[0] / 2, size[2] / 2), z_axis),
        (-y_axis, centre * [1, 2, 1], (size[0] / 2, size[2] / 2), z_axis),
        (x_axis, centre * [0, 1, 1], (size[2] / 2, size[1] / 2), y_axis),
        (-x_axis, centre * [2, 1, 1], (size[2] / 2, size[1] / 2), y_axis),
        (z_axis, centre * [1, 1, 0], (size[0] / 2, size[1] / 2), y_axis),
        (-z_axis, centre * [1, 1, 2], (size[0] / 2, size[1] / 2), y_axis),
    ]
    for i, (normal, c, (hu, hv), up) in enumerate(faces):
        bsdf = diffuse(FLOOR_COLOURS[rng.integers(len(FLOOR_COLOURS))] * rng.uniform(0.5, 1.2)) if i == 0 else \
            diffuse(np.full(3, rng.uniform(0.6, 0.9))) if i == 1 else wall
        scene[f"face_{i}"] = {**rectangle(mi, c, normal, hu, hv, up), "bsdf": bsdf}

    # Windows on the side walls: emitters just inside the wall showing an outdoor view.
    daylight = rng.uniform(3.0, 30.0) * (rng.uniform() < 0.8)
    windows = rng.integers(1, 4) if daylight > 0 else 0
    for k in range(windows):
        normal, c, (hu, hv), up = faces[2 + rng.integers(4)]
        u_dir = np.cross(up, normal)
        w, h = rng.uniform(0.4, min(1.5, hu * 0.8)), rng.uniform(0.4, min(1.0, hv * 0.7))
        pos = c + normal * 0.01 + u_dir * rng.uniform(-(hu - w), hu - w) + up * rng.uniform(-(hv - h) * 0.3, hv - h)
        view = window_view(rng)
        view = view * daylight / max(float(view.mean()), 1e-6)
        scene[f"window_{k}"] = {**rectangle(mi, pos, normal, w, h, up), "emitter": {
            "type": "area", "radiance": {"type": "bitmap", "bitmap": mi.Bitmap(view.astype(np.float32)), "raw": True}}}

    # Ceiling panels and spot lights.
    for k in range(rng.integers(0 if windows else 1, 4)):
        pos = np.array([rng.uniform(0.5, size[0] - 0.5), size[1] - 0.01, rng.uniform(0.5, size[2] - 0.5)])
        half = rng.uniform(0.15, 0.6)
        colour = WARM_WHITE ** rng.uniform(0, 1.5) * rng.uniform(5, 30)
        scene[f"panel_{k}"] = {**rectangle(mi, pos, -y_axis, half, half * rng.uniform(0.3, 1), z_axis),
                               "emitter": {"type": "area", "radiance": {"type": "rgb", "value": colour.tolist()}}}
    for k in range(int(rng.uniform() < 0.3)):
        pos = np.array([rng.uniform(0.3, size[0] - 0.3), size[1] - 0.05, rng.uniform(0.3, size[2] - 0.3)])
        target = np.array([rng.uniform(0, size[0]), 0.0, rng.uniform(0, size[2])])
        scene[f"spot_{k}"] = {"type": "spot", "intensity": {"type": "rgb", "value": (WARM_WHITE * rng.uniform(5, 40)).tolist()},
                              "cutoff_angle": float(rng.uniform(15, 40)),
                              "to_world": mi.ScalarTransform4f().look_at(origin=pos.tolist(), target=target.tolist(),
                                                                         up=[1.0, 0.0, 0.0] if abs(target[0] - pos[0]) < 1e-3 else [0.0, 1.0, 0.0])}

    # Furniture blocks on the floor, and a camera point outside them.
    boxes = []
    for k in range(rng.integers(1, 7)):
        half = np.array([rng.uniform(0.2, 1.0), rng.uniform(0.2, 0.9), rng.uniform(0.2, 1.0)])
        c = np.array([rng.uniform(half[0], size[0] - half[0]), half[1], rng.uniform(half[2], size[2] - half[2])])
        boxes.append((c, half))
        scene[f"box_{k}"] = {"type": "cube", "bsdf": diffuse(rng.uniform(0.05, 0.8, 3)),
                             "to_world": mi.ScalarTransform4f().translate(c.tolist()) @ mi.ScalarTransform4f().scale(half.tolist())}
    for _ in range(100):
        eye = np.array([rng.uniform(0.5, size[0] - 0.5), rng.uniform(1.0, min(1.8, size[1] - 0.3)), rng.uniform(0.5, size[2] - 0.5)])
        if all((np.abs(eye - c) > half + 0.2).any() for c, half in boxes):
            break
    return scene, eye


def offset_scene(scene: dict, offset: np.ndarray, prefix: str) -> dict:
    """Copy of a room's objects translated by `offset`, with keys prefixed (to pack rooms into one scene)."""
    mi = backend.mitsuba()
    shift = mi.ScalarTransform4f().translate(offset.tolist())
    moved = {}
    for key, obj in scene.items():
        if key in ("type", "integrator"):
            continue
        moved[prefix + key] = {**obj, "to_world": shift @ obj["to_world"]}
    return moved


def texel_rays(height: int, spp: int, rng: np.random.Generator) -> np.ndarray:
    """Directions (H * 2H * spp, 3), `spp` per texel, uniform over each texel's solid angle, texel-major."""
    n = height * 2 * height * spp
    rows, cols = np.divmod(np.arange(height * 2 * height).repeat(spp), 2 * height)
    cos_edges = np.cos(np.arange(height + 1) / height * np.pi)
    cos_t = cos_edges[rows] + rng.uniform(size=n) * (cos_edges[rows + 1] - cos_edges[rows])
    phi = (cols + rng.uniform(size=n)) / (2 * height) * 2 * np.pi
    return directions_from_angles(np.arccos(np.clip(cos_t, -1, 1)), phi)


def render_equirects(rooms: list[tuple[dict, np.ndarray]], height: int, spp: int, seed: int) -> np.ndarray:
    """(R, H, 2H, 3) radiance arriving at each room's eye from each texel direction, path-traced in one launch.

    The closed rooms are packed side by side (ROOM_SPACING apart) into one Mitsuba scene, so the
    JIT compiles one kernel for the whole batch instead of one per map.
    """
    mi = backend.mitsuba()
    packed: dict = {"type": "scene", "integrator": {"type": "path", "max_depth": MAX_DEPTH}}
    origins = []
    for r, (scene, eye) in enumerate(rooms):
        offset = np.array([r * ROOM_SPACING, 0.0, 0.0])
        packed.update(offset_scene(scene, offset, f"room{r}_"))
        origins.append(eye + offset)
    loaded = mi.load_dict(packed)
    rng = np.random.default_rng(seed)
    per_room = height * 2 * height * spp
    d = np.concatenate([texel_rays(height, spp, rng) for _ in rooms]).astype(np.float32)
    o = np.repeat(np.array(origins), per_room, axis=0).astype(np.float32)
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(seed, len(d))
    ray = mi.RayDifferential3f(o=mi.Point3f(*o.T), d=mi.Vector3f(*d.T))
    colour, _, _ = loaded.integrator().sample(loaded, sampler, ray)
    radiance = np.array(colour).T.astype(np.float64).reshape(len(rooms), height, 2 * height, spp, 3).mean(3)
    return radiance.astype(np.float32)


def fill_dropouts(env: np.ndarray, ratio: float = 0.3) -> np.ndarray:
    """Replace texels far darker than their 3x3 neighbourhood (all paths missed the lights) by its median."""
    padded = np.concatenate([env[:, -1:], env, env[:, :1]], axis=1)  # wrap in azimuth
    median = median_filter(padded, size=(3, 3, 1), mode="nearest")[:, 1:-1]
    lum, local = env.mean(-1), median.mean(-1)
    return np.where((lum < ratio * local)[..., None], median, env)


def indoor_envmaps(height: int, rng: np.random.Generator, count: int) -> np.ndarray:
    """`count` random (count, H, 2H, 3) float32 indoor maps: furnished, lit rooms seen from a point inside."""
    rooms = [room_scene(rng) for _ in range(count)]
    return np.stack([fill_dropouts(env) for env in render_equirects(rooms, height, SPP, int(rng.integers(2**31)))])
