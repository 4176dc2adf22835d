"""NumPy reference of particle-based volume rendering: the plan's particle sets, each
pixel-centre ray against every sphere near it (float64), the nearest entry kept (the
depth test), its colour (the exact TF's, stored with the particle), opaque; the sets
averaged.

As GL does with points, a particle whose centre lies outside the view's clip volume is
not drawn (``sprites``). With clip planes or a crop box, a particle counts on a pixel's ray
where its centre's projection on the ray lies in the ray's kept part (``sprites.kept_ranges``,
the fragment shader's test); spheres that miss the kept region are dropped beforehand.
With opaque geometry the kept part ends at the ray's first surface (``exact_geometry``'s
float64 hit, GLSL ``GEOMETRY``), and the surface's lit colour is composited behind each
set's image (as behind their average: the operator is linear in the image).
"""

from __future__ import annotations

import numpy as np

from .exact_geometry import surface_behind, surface_hits
from .sprites import kept_ranges, sprite_pixel_pairs


def render_plan(plan, lut_exact=False):
    """(H, W, 4) float64 premultiplied RGBA, row 0 on top. ``lut_exact`` is accepted for
    the common interface: the particles carry the exact TF's colour anyway."""
    scene = plan.scene
    W, H = scene.width, scene.height
    out = np.zeros((H * W, 4))
    t_surface = None
    if scene.geometry:     # the ray ends at its first surface (GLSL: GEOMETRY)
        t_surface, surface_color = surface_hits(scene)
    for k, particle_set in enumerate(plan.sets):
        gradients = None if plan.gradients is None else plan.gradients[k]
        out += first_hits(scene, plan.radius, particle_set.points, particle_set.colors, gradients, t_surface)
    out /= plan.repetitions
    if t_surface is not None:
        out = surface_behind(out, t_surface, surface_color)
    return out.reshape(H, W, 4)


def first_hits(scene, radius, points, colors, gradients=None, t_end=None):
    """(H * W, 4): per pixel the colour (alpha 1) of the first sphere its ray enters, or 0;
    with ``gradients`` (lit), that colour lit with the sphere's gradient along the pixel's
    ray (GLSL ``shadeBlinnPhong``). ``t_end`` (per pixel, optional): the ray ends there
    (its first surface), particles whose centre projects beyond it do not count."""
    W, H = scene.width, scene.height
    p = np.asarray(points, np.float64)
    kept, origins, dirs, chunks = sprite_pixel_pairs(scene, p, radius)
    p, colors = p[kept], np.asarray(colors, np.float64)[kept]
    keep0, keep1 = kept_ranges(scene, origins, dirs)
    if t_end is not None:
        keep1 = np.minimum(keep1, t_end)
    best = np.full(W * H, np.inf)
    owner = np.full(W * H, -1, np.int64)
    for ids, pixel in chunks:
        v = p[ids] - origins[pixel]
        t = np.einsum("ij,ij->i", v, dirs[pixel])
        off = v - t[:, None] * dirs[pixel]
        miss = radius * radius - np.einsum("ij,ij->i", off, off)
        half_chord = np.sqrt(np.maximum(miss, 0.0))
        hit = (miss >= 0) & (t + half_chord > 0) & (t >= keep0[pixel]) & (t <= keep1[pixel])
        t_hit = np.maximum(t - half_chord, 0.0)
        pixel, t_hit, who = pixel[hit], t_hit[hit], ids[hit]
        order = np.lexsort((t_hit, pixel))
        pixel, t_hit, who = pixel[order], t_hit[order], who[order]
        first = np.ones(pixel.size, bool)
        first[1:] = pixel[1:] != pixel[:-1]
        pixel, t_hit, who = pixel[first], t_hit[first], who[first]
        closer = t_hit < best[pixel]
        best[pixel[closer]] = t_hit[closer]
        owner[pixel[closer]] = who[closer]
    out = np.zeros((W * H, 4))
    hit = owner >= 0
    out[hit, :3] = colors[owner[hit]]
    if gradients is not None:
        out[hit, :3] = lit_colors(scene, out[hit, :3], np.asarray(gradients, np.float64)[kept][owner[hit]],
                                  dirs[hit])
    out[hit, 3] = 1.0
    return out


def lit_colors(scene, colors, gradients, dirs):
    """Straight colours of points lit with their gradients along the pixels' rays."""
    from ..model.field import gradient_epsilon
    from .shading import scene_lights, shade_blinn_phong
    return shade_blinn_phong(colors, gradients, dirs, scene.phong, gradient_epsilon(scene.volume), scene_lights(scene))
