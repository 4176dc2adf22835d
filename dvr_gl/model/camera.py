"""The camera and the lights, and the default views of a volume."""

from __future__ import annotations

import math

import numpy as np

from .checks import _finite_number, _vector3


class Camera:
    """A pinhole (``fov`` vertical, degrees) or orthographic (``ortho_height``) camera.

    Rays start at the eye (perspective) or on the plane through the eye normal to the
    view direction (orthographic); nothing behind that start is seen.
    """

    def __init__(self, eye, target, up=(0.0, 1.0, 0.0), fov=30.0, ortho_height=None):
        self.eye = _vector3("eye", eye)
        self.target = _vector3("target", target)
        self.up = _vector3("up", up)
        view = self.target - self.eye
        dist = float(np.linalg.norm(view))
        if dist <= 1e-12 * max(1.0, float(np.abs(self.eye).max())):
            raise ValueError(f"eye must differ from target, both are {tuple(self.eye.tolist())}")
        forward = view / dist
        up_len = float(np.linalg.norm(self.up))
        if up_len == 0:
            raise ValueError(f"up must be a non-zero vector, got {tuple(self.up.tolist())}")
        right = np.cross(forward, self.up / up_len)
        if np.linalg.norm(right) < 1e-9:
            raise ValueError(f"up {tuple(self.up.tolist())} is parallel to the view direction {tuple(forward.tolist())}")
        right /= np.linalg.norm(right)
        self.forward = forward
        self.right = right
        self.true_up = np.cross(right, forward)
        self.distance = dist
        if ortho_height is not None:
            self.ortho_height = _finite_number("ortho_height", ortho_height, positive=True)
            self.fov = None
        else:
            self.fov = _finite_number("fov", fov, positive=True)
            if self.fov >= 180:
                raise ValueError(f"fov must be below 180 degrees, got {fov!r}")
            self.ortho_height = None

    @property
    def is_ortho(self):
        return self.ortho_height is not None

    def screen_scale(self, width, height):
        """Half-extent of the view at unit distance (perspective) or in world units
        (orthographic), as (x, y)."""
        aspect = width / height
        half_h = self.ortho_height / 2 if self.is_ortho else math.tan(math.radians(self.fov) / 2)
        return half_h * aspect, half_h

    def rays(self, width, height):
        """Ray origins and unit directions, each (H, W, 3) float64, row 0 on top,
        through pixel centres."""
        sx, sy = self.screen_scale(width, height)
        x = (2 * (np.arange(width) + 0.5) / width - 1) * sx
        y = (1 - 2 * (np.arange(height) + 0.5) / height) * sy
        xx, yy = np.meshgrid(x, y)
        offset = xx[..., None] * self.right + yy[..., None] * self.true_up
        if self.is_ortho:
            origins = self.eye + offset
            dirs = np.broadcast_to(self.forward, origins.shape).copy()
        else:
            dirs = self.forward + offset
            dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
            origins = np.broadcast_to(self.eye, dirs.shape).copy()
        return origins, dirs

    def key(self):
        return (self.eye.tobytes(), self.target.tobytes(), self.up.tobytes(), self.fov, self.ortho_height)

    def __repr__(self):
        proj = f"ortho_height={self.ortho_height}" if self.is_ortho else f"fov={self.fov}"
        return f"Camera(eye={tuple(self.eye.tolist())}, target={tuple(self.target.tolist())}, up={tuple(self.up.tolist())}, {proj})"


class Light:
    """A light for lit scenes (``Scene(shading=True)`` and isosurfaces).

    ``Light()`` is the headlight: at every sample the light comes from the eye, along
    the ray (L = V), as the contract's default. ``Light(direction, space)`` is a
    directional light: ``direction`` points from the scene towards the light (the L of
    N.L), in world coordinates (``space="world"``) or in the camera's (``space="view"``:
    x right, y up, z towards the viewer). ``intensity`` scales its diffuse and specular
    terms (the ambient term is the scene's, once)."""

    SPACES = ("world", "view")

    def __init__(self, direction=None, space="world", intensity=1.0):
        if space not in self.SPACES:
            raise ValueError(f"space must be one of {', '.join(self.SPACES)}, got {space!r}")
        if direction is not None:
            direction = _vector3("direction", direction)
            length = float(np.linalg.norm(direction))
            if length == 0:
                raise ValueError(f"direction must not be the zero vector, got {tuple(direction.tolist())!r}")
            direction = direction / length
            direction.setflags(write=False)
        self.direction = direction
        self.space = space
        self.intensity = _finite_number("intensity", intensity)
        if self.intensity < 0:
            raise ValueError(f"intensity must be non-negative, got {intensity!r}")

    @property
    def is_headlight(self):
        return self.direction is None

    def world_direction(self, camera):
        """The unit direction towards the light in world coordinates (None: headlight)."""
        if self.direction is None or self.space == "world":
            return self.direction
        x, y, z = self.direction
        return x * camera.right + y * camera.true_up - z * camera.forward

    def key(self):
        return (None if self.direction is None else self.direction.tobytes(), self.space, self.intensity)

    def __repr__(self):
        if self.direction is None:
            return "Light()" if self.intensity == 1.0 else f"Light(intensity={self.intensity})"
        return (f"Light({tuple(round(v, 6) for v in self.direction.tolist())}, space={self.space!r}, "
                f"intensity={self.intensity})")


MAX_LIGHTS = 4


HEADLIGHT = Light()


def anatomical_frame(volume):
    """(front, up) world directions of a volume with an anatomical ``orientation``: the
    anterior direction (where a face looks) and the superior one; None without one."""
    codes = getattr(volume, "orientation", None)
    if codes is None:
        return None
    out = {}
    for axis, letter in enumerate(codes):
        for positive, negative in (("A", "P"), ("S", "I")):
            if letter in (positive, negative):
                v = np.zeros(3)
                v[axis] = 1.0 if letter == positive else -1.0
                out[positive] = v
    return out["A"], out["S"]


def default_camera(volume, azimuth=0.0, elevation=0.0, zoom=1.0, fov=30.0, ortho=False, front=None, up=None):
    """A camera looking at the centre of the volume's (or mesh's) box along -z with +y up, far enough
    that the box's bounding sphere fits the view; ``azimuth`` turns it about +y and then
    ``elevation`` about the camera's right axis (degrees); ``zoom`` > 1 moves closer.
    ``front`` and ``up`` (unit world directions, together) start it elsewhere: the eye on
    the ``front`` side, ``up`` up (``anatomical_frame`` gives a patient's)."""
    zoom = _finite_number("zoom", zoom, positive=True)
    azimuth = _finite_number("azimuth", azimuth)
    elevation = _finite_number("elevation", elevation)
    lo, hi = volume.bounds
    centre = (lo + hi) / 2
    radius = float(np.linalg.norm(hi - lo)) / 2
    az, el = math.radians(azimuth), math.radians(elevation)
    if front is None:
        # Start looking along -z (eye on +z); rotate the eye offset and the up vector together.
        offset = np.array([math.sin(az) * math.cos(el), math.sin(el), math.cos(az) * math.cos(el)])
        up = np.array([-math.sin(az) * math.sin(el), math.cos(el), -math.cos(az) * math.sin(el)])
    else:
        front = _vector3("front", front) / np.linalg.norm(front)
        up0 = _vector3("up", up) / np.linalg.norm(up)
        if abs(float(front @ up0)) > 1e-9:
            raise ValueError(f"front and up must be perpendicular, got {tuple(front)} and {tuple(up0)}")
        horizontal = math.cos(az) * front + math.sin(az) * np.cross(up0, front)
        offset = math.cos(el) * horizontal + math.sin(el) * up0
        up = math.cos(el) * up0 - math.sin(el) * horizontal
    if ortho:
        return Camera(centre + offset * 2 * radius, centre, up, ortho_height=2 * radius / zoom)
    distance = radius / math.sin(math.radians(fov) / 2) / zoom
    return Camera(centre + offset * distance, centre, up, fov=fov)
