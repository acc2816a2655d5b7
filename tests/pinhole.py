"""An independent textbook pinhole camera, to check the renderer's projections against."""

import math

import numpy as np


def pinhole(cam, p, width, height):
    """(row, col) of world point p, from a textbook look-at pinhole camera (rows from the top,
    pixel centres at integer coordinates)."""
    el, az = math.radians(cam.elevation), math.radians(cam.azimuth)
    fwd = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    eye = np.asarray(cam.lookat) - cam.distance * fwd
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    rel = np.asarray(p, float) - eye
    x, y, z = rel @ right, rel @ up, rel @ fwd
    ty = math.tan(math.radians(cam.fovy) / 2)
    tx = ty * width / height
    col = (x / z / tx + 1) / 2 * width - 0.5
    row = (1 - y / z / ty) / 2 * height - 0.5
    return row, col
