"""Capsule proxy vs body meshes: Intersection Volume and Frequency on the embedded interactions.

For each action of the synthetic dataset (one clip per action, seed 0), both persons' bodies are
fitted to the clip's joints (intermask.body.fit_bodies on the given body model: the licensed
SMPL-X file, or the generated stand-in when none is given) and the per-frame IV is measured on
the capsule proxy of the joints and on the fitted meshes (pose correctives included), at one
pitch. Prints the Pearson and Spearman correlation over all frames, the IF of both, the frames
where only one of them sees penetration, and the per-action means.

    python tools/bodies/penetration_agreement.py [--body-model PATH] [--pitch 0.01]
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np
import torch

from intermask.body.export import body_vertices
from intermask.body.fit import FitSettings, fit_bodies
from intermask.body.model import load_body_model
from intermask.body.standin import write_standin_model
from intermask.data.synthetic import generate_clip
from intermask.motion.actions import ACTIONS
from intermask.physics import intersection_volume
from intermask.physics.mesh_volume import mesh_intersection_volume


def ranks(x: np.ndarray) -> np.ndarray:
    order = np.argsort(x, kind="stable")
    result = np.empty(len(x))
    result[order] = np.arange(len(x))
    for value in np.unique(x):  # ties share their mean rank
        tied = x == value
        result[tied] = result[tied].mean()
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--body-model", help="SMPL-X / SMPL-H file or folder (default: the stand-in)"
    )
    parser.add_argument("--pitch", type=float, default=0.01)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    path = args.body_model or write_standin_model(tempfile.mkdtemp(), "smplx")
    model = load_body_model(path, dtype=torch.float64)
    faces = model.faces
    capsule_all, mesh_all, names = [], [], []
    rows = []
    fit_seconds = mesh_seconds = 0.0
    errors = []
    for index, action in enumerate(ACTIONS):
        clip = generate_clip(seed=args.seed, index=index, action=action)
        joints = clip.positions.double()  # (2, T, 22, 3) Y up
        started = time.perf_counter()
        fit = fit_bodies(model, joints)
        fit_seconds += time.perf_counter() - started
        errors.append(fit.error.flatten() * 1000)
        vertices = body_vertices(model, fit.params)  # (2, T, V, 3)
        started = time.perf_counter()
        mesh = mesh_intersection_volume(vertices[0], vertices[1], faces, pitch=args.pitch).numpy()
        mesh_seconds += time.perf_counter() - started
        capsule = intersection_volume(joints[0], joints[1], pitch=args.pitch).numpy()
        capsule_all.append(capsule)
        mesh_all.append(mesh)
        names += [action] * len(mesh)
        rows.append(
            (action, len(mesh), capsule.mean(), mesh.mean(), (capsule > 0).mean(), (mesh > 0).mean(),
             fit.error.mean().item() * 1000)
        )  # fmt: skip
    capsule, mesh = np.concatenate(capsule_all), np.concatenate(mesh_all)
    pearson = np.corrcoef(capsule, mesh)[0, 1]
    spearman = np.corrcoef(ranks(capsule), ranks(mesh))[0, 1]
    print(
        f"body model: {model.path} ({model.kind}, {model.num_vertices} vertices), pitch {args.pitch} m"
    )
    error = torch.cat(errors)
    cpu = next(
        (
            line.split(":", 1)[1].strip()
            for line in open("/proc/cpuinfo")
            if line.startswith("model name")
        ),
        "?",
    )
    print(
        f"CPU: {cpu}, {torch.backends.cpu.get_cpu_capability()}, fit on {FitSettings().threads} thread(s)"
    )
    print(
        f"frames: {len(mesh)} x 2 persons; fit {fit_seconds:.1f} s = "
        f"{fit_seconds * 100 / (2 * len(mesh)):.2f} s per 100 frames per person; "
        f"fitted-body error vs the joints: mean {error.mean():.2f} mm, max {error.max():.2f} mm"
    )
    print(f"mesh IV {mesh_seconds:.1f} s = {mesh_seconds * 100 / len(mesh):.2f} s per 100 frames")
    print(f"Pearson r (per-frame IV) = {pearson:.3f}; Spearman rho = {spearman:.3f}")
    print(f"IF capsule = {(capsule > 0).mean():.3f}, IF mesh = {(mesh > 0).mean():.3f}")
    only_capsule = (capsule > 0) & (mesh == 0)
    only_mesh = (mesh > 0) & (capsule == 0)
    print(
        f"frames penetrating on the capsules only: {only_capsule.sum()}, on the meshes only: {only_mesh.sum()}"
    )
    for label, mask in (("capsules only", only_capsule), ("meshes only", only_mesh)):
        actions, counts = np.unique(np.array(names)[mask], return_counts=True)
        print(f"  {label}: " + ", ".join(f"{a} {c}" for a, c in zip(actions, counts, strict=True)))
    print(
        "\n| action | frames | capsule IV cm^3 | mesh IV cm^3 | capsule IF | mesh IF | fit error mm |"
    )
    print("|---|---|---|---|---|---|---|")
    for action, frames, civ, miv, cif, mif, error in rows:
        print(
            f"| {action} | {frames} | {civ:.1f} | {miv:.1f} | {cif:.2f} | {mif:.2f} | {error:.2f} |"
        )


if __name__ == "__main__":
    main()
