"""Stage 4: antipodal pairs of convex faces (Vogt et al. 2021, Sec. III-B), sub-quadratic search.

(Implementation in progress: see ``find_candidates``.)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from .tolerance import Tolerance


@dataclass(frozen=True)
class Candidates:
    """Antipodal contact pairs in the part frame (metres).

    Attributes
    ----------
    contacts : (n, 2, 3) float64
        Contact points on the part's surface; contact 0 -> contact 1 is the closing axis.
    normals : (n, 2, 3) float64
        Outward unit surface normals at the contacts.
    width : (n,) float64
        ``|contacts[:, 1] - contacts[:, 0]|``.
    faces : (n, 2) int64
        Face indices (into the mesh the search ran on) of the two contacts.
    """

    contacts: np.ndarray
    normals: np.ndarray
    width: np.ndarray
    faces: np.ndarray

    def __post_init__(self):
        n = len(self.width)
        for name, shape in (("contacts", (n, 2, 3)), ("normals", (n, 2, 3)), ("width", (n,)), ("faces", (n, 2))):
            a = getattr(self, name)
            if a.shape != shape:
                raise ValueError(f"Candidates.{name} must have shape {shape}, got {a.shape}")

    def __len__(self) -> int:
        return int(len(self.width))

    @classmethod
    def empty(cls) -> "Candidates":
        return cls(np.zeros((0, 2, 3)), np.zeros((0, 2, 3)), np.zeros(0), np.zeros((0, 2), dtype=np.int64))

    def subset(self, index) -> "Candidates":
        return Candidates(self.contacts[index], self.normals[index], self.width[index], self.faces[index])

    def transformed(self, T: np.ndarray) -> "Candidates":
        """The same candidates after a rigid motion ``T`` (4, 4) of the part."""
        T = np.asarray(T, dtype=np.float64)
        R, t = T[:3, :3], T[:3, 3]
        return Candidates(self.contacts @ R.T + t, self.normals @ R.T, self.width.copy(), self.faces.copy())

    def to_json(self) -> dict:
        return {
            "contacts": self.contacts.tolist(),
            "normals": self.normals.tolist(),
            "width": self.width.tolist(),
            "faces": self.faces.tolist(),
        }

    @classmethod
    def from_json(cls, d: dict) -> "Candidates":
        if not d["width"]:
            return cls.empty()
        return cls(
            np.asarray(d["contacts"], dtype=np.float64).reshape(-1, 2, 3),
            np.asarray(d["normals"], dtype=np.float64).reshape(-1, 2, 3),
            np.asarray(d["width"], dtype=np.float64),
            np.asarray(d["faces"], dtype=np.int64).reshape(-1, 2),
        )


def find_candidates(
    mesh: trimesh.Trimesh,
    convex: np.ndarray,
    *,
    max_opening: float = 0.05,
    beta_deg: float = 2.0,
    epsilon: float = 5e-3,
    mu: float = 0.3,
    tol: Tolerance | None = None,
) -> Candidates:
    raise NotImplementedError("antipodal search: being implemented")
