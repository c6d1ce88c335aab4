"""SMPL-H / SMPL-X body models from the user's licensed files: finding, checking, posing.

The files cannot ship (their licence forbids it): ``--body-model PATH`` names one, or a folder
holding the usual layouts. Two releases are read:

- SMPL-X (``SMPLX_{NEUTRAL,MALE,FEMALE}.npz`` or a ``.pkl`` without chumpy objects): 55 joints,
  pelvis + 21 body + jaw + 2 eyes + 15 + 15 hand joints, 10475 vertices.
- SMPL-H, the extended SMPL+H release used by AMASS (``smplh/{neutral,male,female}/model.npz``)
  or MANO's merged ``SMPLH_{MALE,FEMALE}.pkl``: 52 joints, pelvis + 21 body + 15 + 15 hand
  joints, 6890 vertices.

Only the keys that skinning needs are read (``v_template``, ``shapedirs``, ``posedirs``,
``J_regressor``, ``weights``, ``kintree_table``, ``f``); the first 22 joints of both are the
SMPL body skeleton of :mod:`intermask.motion.skeleton` (checked on load). Posing goes through the
``smplx`` package's linear blend skinning (``smplx.lbs.lbs``), so vertices are what the usual
tools compute; the 22 body joints alone come from the same rest joints by forward kinematics
(no vertices), which is what fitting needs.

Frame: the model's own, Y up, metres, facing +Z with its left on +X, the frame of the project's
joints. Translation follows smplx: the posed pelvis is ``rest_joints(betas)[0] + transl``.
"""

from __future__ import annotations

import pickle
import re
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path
from typing import Literal

import numpy as np
import torch

from intermask.motion.kinematics import forward_kinematics
from intermask.motion.skeleton import NUM_JOINTS, PARENTS

BodyKind = Literal["smplh", "smplx"]
Gender = Literal["neutral", "male", "female"]
GENDERS: tuple[str, ...] = ("neutral", "male", "female")
NUM_MODEL_JOINTS = {"smplh": 52, "smplx": 55}
HAND_JOINTS = 15  # per hand, the same order in SMPL-H and SMPL-X
FACE_JOINTS = {"smplh": 0, "smplx": 3}  # SMPL-X: jaw, left eye, right eye between body and hands
DEFAULT_BETAS = 10
REQUIRED_KEYS = (
    "v_template",
    "shapedirs",
    "posedirs",
    "J_regressor",
    "weights",
    "kintree_table",
    "f",
)
WHERE_TO_GET = (
    "the body-model files are licensed and not shipped: register and download SMPL-X "
    "(SMPLX_NEUTRAL.npz, SMPLX_MALE.npz, SMPLX_FEMALE.npz) from smpl-x.is.tue.mpg.de, or the "
    "extended SMPL+H model (smplh/<gender>/model.npz) from mano.is.tue.mpg.de, and pass the file "
    "or its folder with --body-model (docs/bodies.md)"
)


class BodyModelError(ValueError):
    """A body-model file that is missing, of the wrong kind or gender, or malformed."""


def _file_candidates(folder: Path, kind: BodyKind | None, gender: str) -> list[Path]:
    upper = gender.upper()
    smplx = [
        folder / f"SMPLX_{upper}.npz",
        folder / f"SMPLX_{upper}.pkl",
        folder / "smplx" / f"SMPLX_{upper}.npz",
        folder / "smplx" / f"SMPLX_{upper}.pkl",
    ]
    smplh = [
        folder / gender / "model.npz",
        folder / "smplh" / gender / "model.npz",
        folder / f"SMPLH_{upper}.pkl",
        folder / f"SMPLH_{upper}.npz",
        folder / "smplh" / f"SMPLH_{upper}.pkl",
        folder / "smplh" / f"SMPLH_{upper}.npz",
    ]
    return {"smplx": smplx, "smplh": smplh, None: smplx + smplh}[kind]


def find_body_model_file(
    path: str | Path, *, kind: BodyKind | None = None, gender: str = "neutral"
) -> Path:
    """A body-model file, or a folder holding one in a usual layout -> the file.

    Raises BodyModelError naming every place looked at, and where to get the files."""
    _check_gender(gender)
    path = Path(path)
    if path.is_file():
        return path
    if not path.exists():
        raise BodyModelError(f"{path}: body model not found; {WHERE_TO_GET}")
    looked = _file_candidates(path, kind, gender)
    for candidate in looked:
        if candidate.is_file():
            return candidate
    places = ", ".join(str(p.relative_to(path)) for p in looked)
    raise BodyModelError(
        f"{path}: no {kind or 'SMPL-X or SMPL-H'} body model for gender {gender!r} in this folder "
        f"(looked for {places}); {WHERE_TO_GET}"
    )


def _check_gender(gender: str) -> None:
    if gender not in GENDERS:
        raise BodyModelError(f"gender must be one of {', '.join(GENDERS)}, got {gender!r}")


def gender_of_path(path: Path) -> str | None:
    """The gender a release's file name (or its folder, for smplh/<gender>/model.npz) states."""
    for part in (path.stem, path.parent.name):
        for gender in ("female", "male", "neutral"):  # "female" before "male", which it contains
            if re.search(rf"(^|[_\-.]){gender}($|[_\-.])", part, flags=re.IGNORECASE):
                return gender
    return None


def _read_arrays(path: Path) -> dict[str, object]:
    suffix = path.suffix.lower()
    try:
        if suffix == ".npz":
            loaded = np.load(path, allow_pickle=False)
            if not isinstance(loaded, np.lib.npyio.NpzFile):  # a .npy array under .npz
                raise BodyModelError(
                    f"{path}: not a body-model archive: it holds one array of shape "
                    f"{tuple(loaded.shape)}, not the model's keys"
                )
            with loaded as archive:
                return {key: archive[key] for key in archive.files if key in REQUIRED_KEYS}
        if suffix == ".pkl":
            with path.open("rb") as handle:
                data = pickle.load(handle, encoding="latin1")
            if not isinstance(data, dict):
                raise BodyModelError(
                    f"{path}: expected a pickled dict of arrays, got {type(data).__name__}"
                )
            return {key: data[key] for key in REQUIRED_KEYS if key in data}
    except ModuleNotFoundError as error:
        raise BodyModelError(
            f"{path}: this pickle holds {error.name} objects (the original MANO/SMPL-H release); "
            "use the .npz release, or remove them with smplx's tools/clean_ch.py"
        ) from error
    except (OSError, ValueError, pickle.UnpicklingError, EOFError) as error:
        if isinstance(error, BodyModelError):
            raise
        raise BodyModelError(f"{path}: not a readable body-model file ({error})") from error
    raise BodyModelError(
        f"{path}: body-model files are .npz or .pkl, got {suffix or 'no suffix'!r}"
    )


def _dense(value: object) -> np.ndarray:
    """A scipy sparse matrix (the .pkl J_regressor) or array-like -> a numpy array."""
    if hasattr(value, "toarray"):
        value = value.toarray()
    return np.asarray(value)


@dataclass(frozen=True)
class BodyModel:
    """One gender of SMPL-H or SMPL-X, as tensors (V vertices, J model joints, B betas).

    v_template (V, 3); shapedirs (V, 3, B); posedirs (9 (J-1), 3 V) in smplx's layout;
    j_regressor (J, V); weights (V, J); faces (F, 3) int64; parents: J ints, parents[0] = -1.
    """

    kind: BodyKind
    gender: str
    path: Path
    v_template: torch.Tensor
    shapedirs: torch.Tensor
    posedirs: torch.Tensor
    j_regressor: torch.Tensor
    weights: torch.Tensor
    faces: torch.Tensor
    parents: tuple[int, ...]

    @property
    def num_betas(self) -> int:
        return int(self.shapedirs.shape[-1])

    @property
    def num_joints(self) -> int:
        return len(self.parents)

    @property
    def num_vertices(self) -> int:
        return int(self.v_template.shape[0])

    def to(
        self, device: str | torch.device | None = None, dtype: torch.dtype | None = None
    ) -> BodyModel:
        moved = {
            name: getattr(self, name).to(device=device, dtype=dtype)
            for name in ("v_template", "shapedirs", "posedirs", "j_regressor", "weights")
        }
        return replace(self, faces=self.faces.to(device), **moved)

    def shaped_vertices(self, betas: torch.Tensor) -> torch.Tensor:
        """(..., B) -> (..., V, 3) rest-pose vertices of that shape."""
        return self.v_template + torch.einsum("vcb,...b->...vc", self.shapedirs, betas)

    @cached_property
    def _joint_basis(self) -> tuple[torch.Tensor, torch.Tensor]:
        """J_regressor applied to the template (J, 3) and to the shape directions (J, 3, B)."""
        template = self.j_regressor @ self.v_template
        return template, torch.einsum("jv,vcb->jcb", self.j_regressor, self.shapedirs)

    def rest_joints(self, betas: torch.Tensor) -> torch.Tensor:
        """(..., B) -> (..., J, 3) rest-pose joints (J_regressor of the shaped vertices); linear
        in betas, so computed without the vertices."""
        template, joint_dirs = self._joint_basis
        return template + torch.einsum("jcb,...b->...jc", joint_dirs, betas)

    def body_offsets(self, betas: torch.Tensor) -> torch.Tensor:
        """(..., B) -> (..., 22, 3) rest offset of each body joint from its parent (row 0: the
        rest pelvis itself)."""
        joints = self.rest_joints(betas)[..., :NUM_JOINTS, :]
        parents = list(PARENTS)
        parents[0] = 0
        offsets = joints - joints[..., parents, :]
        return torch.cat((joints[..., :1, :], offsets[..., 1:, :]), dim=-2)

    def body_joints(
        self, betas: torch.Tensor, rotations: torch.Tensor, transl: torch.Tensor
    ) -> torch.Tensor:
        """Posed 22 body joints without vertices: betas (..., B), rotations (..., T, 22, 3, 3)
        (row 0 the global orientation, then local rotations), transl (..., T, 3) ->
        (..., T, 22, 3). Equal to the first 22 joints of :meth:`pose`."""
        offsets = self.body_offsets(betas)[..., None, :, :]  # (..., 1, 22, 3)
        root = offsets[..., 0, :] + transl
        return forward_kinematics(
            rotations, root, offsets.expand(*rotations.shape[:-3], NUM_JOINTS, 3)
        ).positions

    def pose(
        self, betas: torch.Tensor, rotations: torch.Tensor, transl: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Vertices and joints by smplx's linear blend skinning, pose correctives included.

        betas (N, B); rotations (N, J, 3, 3) for every model joint (row 0 the global
        orientation); transl (N, 3) -> vertices (N, V, 3), joints (N, J, 3)."""
        from smplx.lbs import lbs

        count = rotations.shape[0]
        if rotations.shape[1:] != (self.num_joints, 3, 3):
            raise ValueError(
                f"{self.path}: pose needs (N, {self.num_joints}, 3, 3) rotations for a "
                f"{self.kind} model, got {tuple(rotations.shape)}"
            )
        vertices, joints = lbs(
            betas.expand(count, -1),
            rotations,
            self.v_template,
            self.shapedirs,
            self.posedirs,
            self.j_regressor,
            torch.tensor(self.parents, device=rotations.device),
            self.weights,
            pose2rot=False,
        )
        return vertices + transl[:, None, :], joints + transl[:, None, :]


def _check_arrays(path: Path, arrays: dict[str, object], kind: BodyKind | None) -> BodyKind:
    missing = [key for key in REQUIRED_KEYS if key not in arrays]
    if missing:
        raise BodyModelError(
            f"{path}: not an SMPL-H / SMPL-X body model: missing {', '.join(missing)} "
            f"(has {', '.join(sorted(arrays)) or 'none of the model keys'})"
        )
    kintree = _dense(arrays["kintree_table"])
    joints = kintree.shape[-1] if kintree.ndim == 2 else -1
    kinds = {count: name for name, count in NUM_MODEL_JOINTS.items()}
    found = kinds.get(joints)
    if found is None:
        known = ", ".join(f"{count} ({name})" for name, count in NUM_MODEL_JOINTS.items())
        named = {24: " (SMPL, no hand joints)", 16: " (MANO, a hand)", 5: " (FLAME, a head)"}
        raise BodyModelError(
            f"{path}: mismatched joint set: the model has {joints} joints{named.get(joints, '')}, "
            f"expected {known}"
        )
    if kind is not None and found != kind:
        raise BodyModelError(
            f"{path}: mismatched joint set: asked for {kind} ({NUM_MODEL_JOINTS[kind]} joints), "
            f"the file is {found} ({joints} joints)"
        )
    parents = tuple(int(p) for p in kintree[0][:NUM_JOINTS].astype(np.int64))
    if parents[1:] != PARENTS[1:NUM_JOINTS]:
        raise BodyModelError(
            f"{path}: mismatched joint set: the first 22 joints' parents are {parents[1:]}, the "
            f"SMPL body skeleton's are {PARENTS[1:]}"
        )
    vertices = np.shape(arrays["v_template"])[0]
    expected = {
        "v_template": (vertices, 3),
        "weights": (vertices, joints),
        "J_regressor": (joints, vertices),
        "posedirs": (vertices, 3, 9 * (joints - 1)),
    }
    for key, shape in expected.items():
        if tuple(np.shape(_dense(arrays[key]))) != shape:
            raise BodyModelError(
                f"{path}: {key} must be {shape} for {vertices} vertices and {joints} joints, got "
                f"{tuple(np.shape(_dense(arrays[key])))}"
            )
    shapedirs = np.shape(arrays["shapedirs"])
    if len(shapedirs) != 3 or shapedirs[:2] != (vertices, 3):
        raise BodyModelError(f"{path}: shapedirs must be ({vertices}, 3, B), got {shapedirs}")
    faces = np.asarray(arrays["f"])
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.size == 0 or faces.max() >= vertices:
        raise BodyModelError(
            f"{path}: f must be (F, 3) vertex indices below {vertices}, got {faces.shape}"
        )
    return found


def load_body_model(
    path: str | Path,
    *,
    kind: BodyKind | None = None,
    gender: str | None = None,
    num_betas: int = DEFAULT_BETAS,
    device: str | torch.device = "cpu",
    dtype: torch.dtype = torch.float32,
) -> BodyModel:
    """Read and check a body-model file (or find it in a folder, see find_body_model_file).

    kind: "smplx" / "smplh", or None for whatever the file is; gender: None takes the file's
    (neutral when its name says none); a file whose name states another gender is refused.
    num_betas: shape components kept (at most what the file has)."""
    file = find_body_model_file(path, kind=kind, gender=gender or "neutral")
    stated = gender_of_path(file)
    if gender is not None and stated is not None and stated != gender:
        raise BodyModelError(
            f"{file}: wrong gender: asked for {gender!r}, the file is the {stated!r} model "
            f"(pass its {gender} file, or --gender {stated})"
        )
    arrays = _read_arrays(file)
    found = _check_arrays(file, arrays, kind)
    if num_betas < 1:
        raise BodyModelError(f"num_betas must be >= 1, got {num_betas}")
    shapedirs = np.asarray(arrays["shapedirs"])[
        :, :, : min(num_betas, 300)
    ]  # SMPL-X: 300 shape + expressions
    posedirs = _dense(arrays["posedirs"])
    posedirs = posedirs.reshape(-1, posedirs.shape[-1]).T  # (9 (J-1), 3 V), smplx's layout
    kintree = _dense(arrays["kintree_table"]).astype(np.int64)
    parents = (-1, *(int(p) for p in kintree[0][1:]))

    def tensor(value: object) -> torch.Tensor:
        return torch.as_tensor(np.ascontiguousarray(_dense(value), dtype=np.float64)).to(
            device=device, dtype=dtype
        )

    return BodyModel(
        kind=found,
        gender=gender or stated or "neutral",
        path=file,
        v_template=tensor(arrays["v_template"]),
        shapedirs=tensor(shapedirs),
        posedirs=tensor(posedirs),
        j_regressor=tensor(arrays["J_regressor"]),
        weights=tensor(arrays["weights"]),
        faces=torch.as_tensor(np.asarray(arrays["f"]).astype(np.int64), device=device),
        parents=parents,
    )


def full_rotations(
    model: BodyModel, body: torch.Tensor, hands: torch.Tensor | None = None
) -> torch.Tensor:
    """Every model joint's rotation from the body's: body (..., 22, 3, 3), hands (..., 30, 3, 3)
    or None (flat hands) -> (..., J, 3, 3); SMPL-X's jaw and eyes are the identity."""
    lead = body.shape[:-3]
    eye = torch.eye(3, dtype=body.dtype, device=body.device)
    if hands is None:
        hands = eye.expand(*lead, 2 * HAND_JOINTS, 3, 3)
    face = eye.expand(*lead, FACE_JOINTS[model.kind], 3, 3)
    return torch.cat((body, face, hands), dim=-3)
