#!/usr/bin/env python3
"""Issue 47, item 3: a run's export (`OUT/export`, or `cargo xtask export --run OUT`) read by
nerfstudio itself, and compared with what we wrote.

nerfstudio's own `NerfstudioDataParserConfig` parses `transforms.json` with its recentring and
rescaling turned off (`orientation_method="none"`, `center_method="none"`,
`auto_scale_poses=False`, `scale_factor=1.0`, `eval_mode="all"`), so its cameras must be ours
exactly: camera-to-world, intrinsics, image sizes, camera model, distortion. Its dataset loads
the first image, and its depth reader (`get_depth_image_from_path`, with the file's
`depth_unit_scale_factor`) must give the depth that our 16-bit PNG encodes (value * unit).
With nerfstudio's defaults (auto-orient, centre, scale) the cameras are moved, as the README
says: the script records the transform and scale it applied.

Not in CI (nerfstudio pulls in torch). Run once in its own venv:

    python3 -m venv /tmp/nsvenv && /tmp/nsvenv/bin/pip install -r tools/interop/requirements.txt
    /tmp/nsvenv/bin/python tools/interop/nerfstudio_check.py EXPORT_DIR \
        --out bench/results/nerfstudio-roundtrip.json --command "how EXPORT_DIR was made"

It exits 1 when anything differs (cameras beyond 1e-6, intrinsics beyond 1e-4, sizes, the
first image or depth beyond 1e-6).
"""

import argparse
import json
import os
import platform
import sys
from pathlib import Path

import numpy as np
from PIL import Image


def our_frames(export):
    with open(export / "transforms.json") as f:
        t = json.load(f)
    return t, {fr["file_path"]: fr for fr in t["frames"]}


def nerfstudio_outputs(export, **overrides):
    from nerfstudio.data.dataparsers.nerfstudio_dataparser import NerfstudioDataParserConfig

    cfg = NerfstudioDataParserConfig(data=export, eval_mode="all", **overrides)
    return cfg.setup().get_dataparser_outputs(split="train")


def compare(export):
    import nerfstudio
    import torch
    from nerfstudio.cameras.cameras import CameraType
    from nerfstudio.data.datasets.base_dataset import InputDataset
    from nerfstudio.data.utils.data_utils import get_depth_image_from_path

    t, frames = our_frames(export)
    out = nerfstudio_outputs(
        export,
        orientation_method="none",
        center_method="none",
        auto_scale_poses=False,
        scale_factor=1.0,
    )
    cams = out.cameras
    names = [str(Path(p).relative_to(export)) for p in out.image_filenames]
    assert sorted(names) == sorted(frames), (names, list(frames))
    ours = np.stack([np.array(frames[n]["transform_matrix"], dtype=np.float64)[:3] for n in names])
    theirs = cams.camera_to_worlds.double().numpy()
    c2w_err = float(np.abs(ours - theirs).max())
    fx, fy = cams.fx.squeeze(-1).numpy(), cams.fy.squeeze(-1).numpy()
    cx, cy = cams.cx.squeeze(-1).numpy(), cams.cy.squeeze(-1).numpy()
    w, h = cams.width.squeeze(-1).numpy(), cams.height.squeeze(-1).numpy()
    intr_err = float(
        max(
            np.abs(fx - t["fl_x"]).max(),
            np.abs(fy - t["fl_y"]).max(),
            np.abs(cx - t["cx"]).max(),
            np.abs(cy - t["cy"]).max(),
        )
    )
    sizes_equal = bool((w == t["w"]).all() and (h == t["h"]).all())
    types = {CameraType(int(c)).name for c in cams.camera_type.flatten().tolist()}
    distortion_max = (
        0.0 if cams.distortion_params is None else float(cams.distortion_params.abs().max())
    )

    dataset = InputDataset(out)
    first = dataset[0]["image"]
    image_shape = list(first.shape)
    our_png = np.asarray(Image.open(out.image_filenames[0]).convert("RGB"), dtype=np.float32) / 255
    image_err = float(np.abs(first.numpy()[..., :3] - our_png).max())

    unit = out.metadata.get("depth_unit_scale_factor")
    depth_files = out.metadata.get("depth_filenames") or []
    depth_err = None
    if depth_files:
        raw = np.asarray(Image.open(depth_files[0]), dtype=np.float64)
        depth = get_depth_image_from_path(
            filepath=depth_files[0],
            height=int(h[0]),
            width=int(w[0]),
            scale_factor=float(unit),
        )
        depth_err = float(np.abs(depth.squeeze(-1).double().numpy() - raw * t["depth_unit_scale_factor"]).max())

    defaults = nerfstudio_outputs(export)
    default_transform = defaults.dataparser_transform.double().numpy().tolist()

    return {
        "benchmark": "a run's nerfstudio export read by nerfstudio's own dataparser (issue 47, item 3)",
        "script": "tools/interop/nerfstudio_check.py",
        "export": str(export),
        "machine": {"os": platform.system().lower(), "python": platform.python_version()},
        "versions": {
            "nerfstudio": getattr(nerfstudio, "__version__", None)
            or __import__("importlib.metadata").metadata.version("nerfstudio"),
            "torch": torch.__version__,
        },
        "frames": len(names),
        "frames_ours": len(frames),
        "camera_to_world_max_abs_error": c2w_err,
        "intrinsics_max_abs_error": intr_err,
        "image_sizes_equal": sizes_equal,
        "camera_types": sorted(types),
        "distortion_max_abs": distortion_max,
        "first_image_shape": image_shape,
        "first_image_max_abs_error": image_err,
        "depth_files": len(depth_files),
        "depth_unit_scale_factor_read": unit,
        "depth_unit_scale_factor_ours": t["depth_unit_scale_factor"],
        "first_depth_max_abs_error": depth_err,
        "with_nerfstudio_defaults": {
            "note": "auto-orient, centre and scale on: the cameras are moved by this transform and scale",
            "dataparser_transform": default_transform,
            "dataparser_scale": float(defaults.dataparser_scale),
        },
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("export", type=Path)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--command", help="how the export was made, recorded as is")
    args = ap.parse_args()
    result = compare(args.export.resolve())
    result["export_command"] = args.command
    ok = (
        result["frames"] == result["frames_ours"]
        and result["camera_to_world_max_abs_error"] < 1e-6
        and result["intrinsics_max_abs_error"] < 1e-4
        and result["image_sizes_equal"]
        and result["first_image_max_abs_error"] < 1e-6
        and (result["first_depth_max_abs_error"] is None or result["first_depth_max_abs_error"] < 1e-6)
    )
    result["equal"] = ok
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(result, f, indent=1)
        f.write("\n")
    print(json.dumps(result, indent=1))
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
