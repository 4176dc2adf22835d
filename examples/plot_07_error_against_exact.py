"""
Error against the exact image, and ``tolerance=``
=================================================

Every technique approximates the same integral. :func:`dvr_gl.reference.exact` computes
that integral for each pixel in float64 (to about 1e-7), and :mod:`dvr_gl.metrics`
measures how far an image is from it. Exact images are slow to make, so this example
keeps them small: 128 pixels a side.
"""

import matplotlib.pyplot as plt
import numpy as np

import dvr_gl
from dvr_gl import data, metrics
from dvr_gl.formats import to_png_array

head = data.ct_head()
camera = dvr_gl.default_camera(head, azimuth=30, elevation=15, front=(0, -1, 0), up=(0, 0, -1), zoom=1.3)
scene = dvr_gl.Scene(head, data.ct_head_tf(), camera, width=128, height=128)

# cache=False: the exact image is computed here and not stored (by default it is cached
# on disk, named by the scene's digest, and loaded from there next time)
exact = dvr_gl.reference.exact(scene, cache=False)

# %%
# The ray caster's error against the step
# ---------------------------------------
# The step is the distance between samples along a ray, in world units; the head's
# smallest spacing (one voxel along z) is 1.5. The midpoint samples converge at second
# order: halving the step divides the error by about four.

voxel = head.min_spacing
steps = [2.0, 1.0, 0.5, 0.25]
with dvr_gl.Renderer() as renderer:
    images = {s: renderer.render(scene, technique="raycast", step=s * voxel) for s in steps}
errors = {s: metrics.compare(image, exact) for s, image in images.items()}
for s, e in errors.items():
    print(f"step {s:4} voxel: rmse {e['rmse']:.2e}, max abs {e['max_abs']:.2e}, psnr {e['psnr']:.1f} dB")

fig, axes = plt.subplots(1, 3, figsize=(10, 3.3))
axes[0].imshow(to_png_array(exact.astype(np.float32), background=(0, 0, 0)))
axes[0].set_title("exact", fontsize=9)
axes[0].set_axis_off()
shown = axes[1].imshow(np.abs(images[2.0] - exact).max(axis=2), cmap="magma")
axes[1].set_title("error at 2 voxels", fontsize=9)
axes[1].set_axis_off()
fig.colorbar(shown, ax=axes[1], fraction=0.046)
axes[2].loglog(steps, [errors[s]["rmse"] for s in steps], "o-")
axes[2].set_xticks(steps, [f"{s:g}" for s in steps])
axes[2].minorticks_off()
axes[2].set_xlabel("step (voxels)", fontsize=9)
axes[2].set_ylabel("RMSE against exact", fontsize=9)
fig.tight_layout()
plt.show()

# %%
# Asking for an error instead of a step
# -------------------------------------
# ``Renderer.render(scene, tolerance=E)`` chooses the ray caster's step (and whether to
# pre-integrate) for an RMSE of ``E`` against the exact image, from a small pilot render
# of the same view; ``last_choice`` says what it chose. The first call for a scene costs
# the pilot; later ones reuse it.

with dvr_gl.Renderer() as renderer:
    image = renderer.render(scene, tolerance=2e-3)
    choice = renderer.last_choice
print(f"asked for rmse 2.0e-03: step {choice.step_voxels:.2f} voxel, "
      f"pre-integrated: {choice.preintegrate}, achieved rmse {metrics.rmse(image, exact):.2e}")
