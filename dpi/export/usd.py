"""One USD stage per scene (`.usda`, with usd-core): the mesh, one UsdPreviewSurface material per sample, and a
variant set `sample` that switches the mesh's material and the dome light's env map, so a pipeline picks a sample
by name. Textures and env maps are files beside the stage, named by relative paths."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dpi.export.asset import AssetMesh, AssetSample
from dpi.io.atomic import atomic_path

ROOT = "/asset"
VARIANT_SET = "sample"
CHANNELS = {"albedo": ("diffuseColor", "rgb", "sRGB"), "roughness": ("roughness", "r", "raw"),
            "metallic": ("metallic", "r", "raw")}
"""per texture: the UsdPreviewSurface input it drives, the UsdUVTexture output it uses, its colour space"""


def _material(stage, name: str, files: dict[str, str]):
    """A UsdPreviewSurface material reading the three textures `files` (relative paths) through primvar `st`."""
    from pxr import Sdf, UsdShade

    path = f"{ROOT}/materials/{name}"
    material = UsdShade.Material.Define(stage, path)
    surface = UsdShade.Shader.Define(stage, f"{path}/surface")
    surface.CreateIdAttr("UsdPreviewSurface")
    reader = UsdShade.Shader.Define(stage, f"{path}/st")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    st = reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    for texture, (surface_input, output, space) in CHANNELS.items():
        shader = UsdShade.Shader.Define(stage, f"{path}/{texture}")
        shader.CreateIdAttr("UsdUVTexture")
        shader.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(files[texture])
        shader.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(st)
        shader.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set(space)
        for wrap in ("wrapS", "wrapT"):
            shader.CreateInput(wrap, Sdf.ValueTypeNames.Token).Set("clamp")
        kind = Sdf.ValueTypeNames.Float3 if output == "rgb" else Sdf.ValueTypeNames.Float
        source = shader.CreateOutput(output, kind)
        target = Sdf.ValueTypeNames.Color3f if output == "rgb" else Sdf.ValueTypeNames.Float
        surface.CreateInput(surface_input, target).ConnectToSource(source)
    material.CreateSurfaceOutput().ConnectToSource(surface.ConnectableAPI(), "surface")
    return material


def write_usd(path: str | Path, mesh: AssetMesh, samples: list[AssetSample], textures: dict[str, dict[str, str]],
              envmaps: dict[str, str]) -> None:
    """Write the stage to `path` atomically: `textures[sample.name]` maps albedo/roughness/metallic to files and
    `envmaps[sample.name]` names the dome light's map, both relative to `path`; `samples[0]` is selected."""
    from pxr import Sdf, Usd, UsdGeom, UsdLux, UsdShade, Vt

    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = UsdGeom.Xform.Define(stage, ROOT)
    stage.SetDefaultPrim(root.GetPrim())
    geom = UsdGeom.Mesh.Define(stage, f"{ROOT}/object")
    geom.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(mesh.positions))
    geom.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(mesh.faces), 3, np.int32)))
    geom.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(mesh.faces.astype(np.int32).ravel()))
    geom.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(mesh.normals))
    geom.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    geom.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    geom.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([mesh.positions.min(0), mesh.positions.max(0)])))
    st = UsdGeom.PrimvarsAPI(geom).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
    st.Set(Vt.Vec2fArray.FromNumpy(np.stack([mesh.uvs[:, 0], 1.0 - mesh.uvs[:, 1]], -1).astype(np.float32)))
    binding = UsdShade.MaterialBindingAPI.Apply(geom.GetPrim())
    light = UsdLux.DomeLight.Define(stage, f"{ROOT}/light")
    light.CreateTextureFormatAttr(UsdLux.Tokens.latlong)
    file_attr = light.CreateTextureFileAttr()
    materials = {s.name: _material(stage, s.label, textures[s.name]) for s in samples}
    variants = root.GetPrim().GetVariantSets().AddVariantSet(VARIANT_SET)
    for sample in samples:
        variants.AddVariant(sample.label)
        variants.SetVariantSelection(sample.label)
        with variants.GetVariantEditContext():
            binding.Bind(materials[sample.name])
            file_attr.Set(Sdf.AssetPath(envmaps[sample.name]))
    variants.SetVariantSelection(samples[0].label)
    with atomic_path(path) as tmp:
        stage.GetRootLayer().Export(str(tmp))
