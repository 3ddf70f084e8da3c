import numpy as np
import pytest

import paramlod as pl


def sphere_disc(camera, center=(0, 0, 0), radius=1.0):
    """Analytic silhouette mask of a sphere seen by ``camera`` (pixel centres)."""
    w, h = camera.size
    ys, xs = np.mgrid[0:h, 0:w]
    ndc = np.stack([(xs + 0.5) / w * 2 - 1, 1 - (ys + 0.5) / h * 2], axis=-1)
    inv = np.linalg.inv(camera.projection @ camera.view)
    near = np.concatenate([ndc, -np.ones((h, w, 1)), np.ones((h, w, 1))], axis=-1) @ inv.T
    far = np.concatenate([ndc, np.ones((h, w, 1)), np.ones((h, w, 1))], axis=-1) @ inv.T
    o = near[..., :3] / near[..., 3:]
    d = far[..., :3] / far[..., 3:] - o
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    oc = o - np.asarray(center, float)
    b = np.sum(oc * d, axis=-1)
    c = np.sum(oc * oc, axis=-1) - radius ** 2
    disc = b * b - c
    hit = disc >= 0
    t = -b - np.sqrt(np.where(hit, disc, 0))
    # linear view depth of the front hit
    pts = o + t[..., None] * d
    depth = -(np.concatenate([pts, np.ones((h, w, 1))], axis=-1) @ camera.view.T)[..., 2]
    return hit, np.where(hit, depth, np.inf)


def iou(a, b):
    return np.logical_and(a, b).sum() / max(1, np.logical_or(a, b).sum())


@pytest.fixture
def sphere_scene():
    s = pl.Scene()
    s.add("sphere")
    return s
