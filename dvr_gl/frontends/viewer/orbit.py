"""The viewer's camera: an orbit about a target point, turned like a trackball.

:class:`Orbit` keeps an orientation matrix rather than angles, so dragging over the poles
never flips the view; :meth:`Orbit.camera` gives the :class:`dvr_gl.Camera` a frame is
rendered with, and :meth:`Orbit.ray` the ray under a window point (for picking).
"""

from __future__ import annotations

import math

import numpy as np

from ...model.camera import Camera


def _rotation(axis, angle):
    """The 3x3 matrix turning by ``angle`` radians about unit ``axis`` (right-handed)."""
    x, y, z = axis
    c, s = math.cos(angle), math.sin(angle)
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return c * np.eye(3) + s * k + (1 - c) * np.outer(axis, axis)


class Orbit:
    """An orbiting camera: a target point, an orientation (the columns of ``rotation``
    are the camera's right, up and back axes in world space) and a distance.

    Rotations turn the orientation matrix about the camera's own axes, so there are no
    poles to flip over (no angles are stored). Orthographic views show a height of
    ``2 * distance * tan(fov / 2)`` at the target, the height a perspective view shows
    there, and put the eye ``2 * radius`` from the target (outside the volume's bounding
    sphere), as :func:`dvr_gl.default_camera` does.
    """

    def __init__(self, volume, azimuth=None, elevation=None, zoom=1.0, fov=30.0, ortho=False):
        self.volume = volume
        lo, hi = volume.bounds
        self.radius = float(np.linalg.norm(hi - lo)) / 2
        self.fov = float(fov)
        self.start = dict(azimuth=azimuth, elevation=elevation, zoom=zoom, fov=fov, ortho=ortho)
        self.reset()

    def reset(self):
        """Back to the command line's view (``inputs.first_camera`` of its angles)."""
        from ..inputs import first_camera
        cam = first_camera(self.volume, **self.start)
        self.ortho = cam.is_ortho
        self.target = cam.target.copy()
        self.rotation = np.column_stack([cam.right, cam.true_up, -cam.forward])
        if self.ortho:
            self.distance = cam.ortho_height / (2 * math.tan(math.radians(self.fov) / 2))
        else:
            self.distance = cam.distance

    @property
    def right(self):
        return self.rotation[:, 0]

    @property
    def up(self):
        return self.rotation[:, 1]

    @property
    def back(self):
        return self.rotation[:, 2]

    @property
    def ortho_height(self):
        return 2 * self.distance * math.tan(math.radians(self.fov) / 2)

    def camera(self) -> Camera:
        if self.ortho:
            return Camera(self.target + 2 * self.radius * self.back, self.target, self.up,
                          ortho_height=self.ortho_height)
        return Camera(self.target + self.distance * self.back, self.target, self.up, fov=self.fov)

    def _orthonormalise(self):
        back = self.back / np.linalg.norm(self.back)
        right = np.cross(self.up, back)
        right /= np.linalg.norm(right)
        self.rotation = np.column_stack([right, np.cross(back, right), back])

    def orbit(self, yaw, pitch):
        """Turn the eye about the target: ``yaw`` radians about the camera's up axis
        (positive moves the eye to the right), then ``pitch`` about its right axis
        (positive moves it up)."""
        right, up = self.right.copy(), self.up.copy()
        turn = _rotation(right, -pitch) @ _rotation(up, yaw)
        self.rotation = turn @ self.rotation
        self._orthonormalise()

    def zoom(self, factor):
        """``factor`` > 1 moves closer (perspective) or magnifies (orthographic)."""
        self.distance = max(self.distance / factor, 1e-4 * self.radius)

    def pan(self, right, up):
        """Move the target (and the eye with it) by world distances along the camera's
        right and up axes."""
        self.target = self.target + right * self.right + up * self.up

    def world_per_pixel(self, window_height):
        """World size of one window pixel at the target's depth."""
        return self.ortho_height / max(window_height, 1)

    def ray(self, x, y, width, height):
        """Origin and unit direction of the ray through window point (x, y) of a
        ``width`` x ``height`` window (continuous coordinates, y down)."""
        cam = self.camera()
        sx, sy = cam.screen_scale(width, height)
        nx, ny = 2 * x / width - 1, 1 - 2 * y / height
        offset = nx * sx * cam.right + ny * sy * cam.true_up
        if cam.is_ortho:
            return cam.eye + offset, cam.forward.copy()
        d = cam.forward + offset
        return cam.eye.copy(), d / np.linalg.norm(d)
