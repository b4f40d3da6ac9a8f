"""One glTF binary (.glb) per scene, written with pygltflib: the mesh with its UVs, one metallic-roughness
material per sample, the samples as KHR_materials_variants variants (the first the default), and each method's
spread maps as extra textures described in the materials' `extras`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pygltflib as gl

from dpi.export.asset import AssetMesh, AssetSample, png_bytes, sample_textures
from dpi.io.atomic import atomic_path

VARIANTS = "KHR_materials_variants"
LINEAR, CLAMP = 9729, 33071
"""glTF sampler constants: bilinear lookups clamped at the edges, as the renderer samples the textures"""


class _Blob:
    """The binary chunk and its buffer views, each view 4-byte aligned."""

    def __init__(self, gltf: gl.GLTF2):
        self.gltf, self.data = gltf, bytearray()

    def view(self, payload: bytes, target: int | None = None) -> int:
        self.data += b"\0" * (-len(self.data) % 4)
        self.gltf.bufferViews.append(gl.BufferView(buffer=0, byteOffset=len(self.data), byteLength=len(payload),
                                                   target=target))
        self.data += payload
        return len(self.gltf.bufferViews) - 1

    def accessor(self, array: np.ndarray, kind: str, component: int, target: int, bounds: bool = False) -> int:
        view = self.view(array.tobytes(), target)
        extra = {"min": array.min(0).tolist(), "max": array.max(0).tolist()} if bounds else {}
        self.gltf.accessors.append(gl.Accessor(bufferView=view, componentType=component, count=len(array),
                                               type=kind, **extra))
        return len(self.gltf.accessors) - 1

    def texture(self, pixels: np.ndarray, name: str) -> int:
        self.gltf.images.append(gl.Image(bufferView=self.view(png_bytes(pixels)), mimeType="image/png", name=name))
        self.gltf.textures.append(gl.Texture(sampler=0, source=len(self.gltf.images) - 1, name=name))
        return len(self.gltf.textures) - 1


def write_glb(path: str | Path, mesh: AssetMesh, samples: list[AssetSample], extras: dict[str, dict[str, Any]],
              spread: dict[str, dict[str, np.ndarray]], note: str) -> None:
    """Write the asset to `path` atomically. `samples[0]` is the default material; `extras[sample.name]` goes into its
    material's extras (its env map's files, ...); `spread[method]` holds 8-bit spread maps embedded as textures and
    named in that method's materials' extras; `note` explains them in the asset's extras."""
    gltf = gl.GLTF2(asset=gl.Asset(generator="dpi", version="2.0"), scene=0, scenes=[gl.Scene(nodes=[0])],
                    nodes=[gl.Node(mesh=0, name="object")], samplers=[gl.Sampler(magFilter=LINEAR, minFilter=LINEAR,
                                                                                  wrapS=CLAMP, wrapT=CLAMP)])
    blob = _Blob(gltf)
    attributes = gl.Attributes(
        POSITION=blob.accessor(mesh.positions, gl.VEC3, gl.FLOAT, gl.ARRAY_BUFFER, bounds=True),
        NORMAL=blob.accessor(mesh.normals, gl.VEC3, gl.FLOAT, gl.ARRAY_BUFFER),
        TEXCOORD_0=blob.accessor(mesh.uvs, gl.VEC2, gl.FLOAT, gl.ARRAY_BUFFER))
    indices = blob.accessor(mesh.faces.reshape(-1, 1), gl.SCALAR, gl.UNSIGNED_INT, gl.ELEMENT_ARRAY_BUFFER)
    spread_textures = {method: {name: blob.texture(pixels, f"{method} {name}") for name, pixels in maps.items()}
                       for method, maps in spread.items()}
    for sample in samples:
        textures = sample_textures(sample, mesh)
        pbr = gl.PbrMetallicRoughness(
            baseColorTexture=gl.TextureInfo(index=blob.texture(textures["base_color"], f"{sample.name} base colour")),
            metallicRoughnessTexture=gl.TextureInfo(index=blob.texture(textures["metallic_roughness"],
                                                                       f"{sample.name} metallic roughness")),
            metallicFactor=1.0, roughnessFactor=1.0)
        own = {"method": sample.method, "sample": sample.k, **extras.get(sample.name, {}),
               **({"spread_textures": spread_textures[sample.method]} if sample.method in spread_textures else {})}
        gltf.materials.append(gl.Material(name=sample.name, pbrMetallicRoughness=pbr, extras={"dpi": own}))
    mappings = [{"material": i, "variants": [i]} for i in range(len(samples))]
    gltf.meshes.append(gl.Mesh(name="object", primitives=[gl.Primitive(attributes=attributes, indices=indices,
                                                                       material=0,
                                                                       extensions={VARIANTS: {"mappings": mappings}})]))
    gltf.extensionsUsed = [VARIANTS]
    gltf.extensions = {VARIANTS: {"variants": [{"name": s.name} for s in samples]}}
    gltf.extras = {"dpi": {"note": note}}
    gltf.buffers = [gl.Buffer(byteLength=len(blob.data))]
    gltf.set_binary_blob(bytes(blob.data))
    with atomic_path(path) as tmp:
        gltf.save_binary(str(tmp))
