"""dvr_gl at a fixed RMSE on narrow opacity spikes, beside VTK's one-voxel frame.

Scenes: the Marschner-Lobb signal (41^3) with an opacity spike 2 % of its value range
wide at the middle of the range (the signal's wavy 0.5 shell: detail everywhere the band
can be), the bundled CT head with the spike 1 % wide of ``apps/tolerance_vs_vtk.py``
(bone's edge), and smooth noise (turbulence-like) with a 2 % spike. For each: the exact image (``reference.exact``) at ``--error-size``; VTK's
GPU ray caster at one voxel (its RMSE there); ``Renderer.render(scene, tolerance=E)``
(its pilot outside the timed frames), and the same with the walk by reach asked for
(``preintegrate=True, refine=8, refine_walk="reach"``); and, for each way of sampling (plain, pre-integrated,
refined with even parts, refined walked by reach, walked by crossings), the longest step of a ladder from 4 to
1/8 voxel (2^(1/4) apart) whose RMSE is at most ``E``. VTK's frame, the tolerance frame and
those candidates are timed in one round robin at ``--size`` (median of ``--repeats``).

    LP_NUM_THREADS=2 python scripts/narrow_spike_numbers.py [--target 5e-3] [--out FILE.md]
"""

import argparse
import os
import statistics
import sys

import numpy as np

import dvr_gl
from dvr_gl import metrics, reference
from dvr_gl.bench.common import datasets, interleaved_frames, oblique_camera
from dvr_gl.bench.vtk_peer import VTKPeer
from dvr_gl.data.phantoms import marschner_lobb
from dvr_gl.formats import atomic_write

LADDER = tuple(4.0 * 2.0 ** (-k / 4) for k in range(21))
WAYS = (("plain", {}), ("pre-int.", {"preintegrate": True}),
        ("refine 4, even", {"preintegrate": True, "refine": 4}),
        ("refine 8, even", {"preintegrate": True, "refine": 8}),
        ("refine 8, reach", {"preintegrate": True, "refine": 8, "refine_walk": "reach"}),
        ("refine 12, reach", {"preintegrate": True, "refine": 12, "refine_walk": "reach"}),
        ("refine 2, crossings", {"preintegrate": True, "refine": 2, "refine_walk": "crossings"}),
        ("refine 4, crossings", {"preintegrate": True, "refine": 4, "refine_walk": "crossings"}))


REACH = {"preintegrate": True, "refine": 8, "refine_walk": "reach"}


def spike_tf(volume, centre, width, color):
    """Opacity 0.9 at ``centre`` (a fraction of the value range), zero beyond ``width / 2``
    of the range either side."""
    lo, hi = volume.data_range
    c, w = lo + centre * (hi - lo), width * (hi - lo)
    return dvr_gl.TransferFunction(color=[(lo, *color[0]), (c, *color[1]), (hi, *color[2])],
                                   opacity=[(lo, 0.0), (c - w / 2, 0.0), (c, 0.9), (c + w / 2, 0.0), (hi, 0.0)],
                                   unit_distance=volume.min_spacing)


COLORS = ((0.9, 0.6, 0.4), (1.0, 0.95, 0.8), (0.6, 0.7, 1.0))


def smooth_noise(n, cutoff, seed):
    """Gaussian-filtered white noise on n^3 samples (a Gaussian of ``cutoff`` cycles per
    side in the frequency domain), scaled to [0, 1]: detail everywhere, like turbulence
    (as in scripts/validate_tolerance.py)."""
    rng = np.random.default_rng(seed)
    k = np.fft.fftfreq(n) * n
    kx, ky, kz = np.meshgrid(k, k, k, indexing="ij")
    spectrum = np.fft.fftn(rng.standard_normal((n, n, n))) * np.exp(-(kx ** 2 + ky ** 2 + kz ** 2) / (2 * cutoff ** 2))
    field = np.real(np.fft.ifftn(spectrum))
    return dvr_gl.Volume(((field - field.min()) / (field.max() - field.min())).astype(np.float32), spacing=(1, 1, 1))


def scenes(names):
    """[(name, volume, tf, camera)] of ``names`` from ml (the Marschner-Lobb spike), head
    (the CT-head spike) and noise (smooth noise, 64^3 at 8 cycles, a 2 % spike at the
    middle of its range)."""
    out = []
    if "ml" in names:
        ml = marschner_lobb(41)
        out.append(("Marschner-Lobb spike (2 %)", ml, spike_tf(ml, 0.5, 0.02, COLORS),
                    oblique_camera(ml, front=(0, 0, 1), up=(0, 1, 0))))
    if "head" in names:
        (_, head, _, camera), = datasets(["head"])
        out.append(("CT-head spike (1 %)", head, spike_tf(head, 0.55, 0.01, COLORS), camera))
    if "noise" in names:
        noise = smooth_noise(64, 8.0, 2)
        out.append(("smooth-noise spike (2 %)", noise, spike_tf(noise, 0.5, 0.02, COLORS),
                    oblique_camera(noise, front=(0, 0, 1), up=(0, 1, 0))))
    return out


def words(step, way):
    return f"{step:.3g}, {way}"


def choice_words(choice):
    if not choice.preintegrate:
        return f"{choice.step_voxels:.3g}, plain"
    if choice.refine == 1:
        return f"{choice.step_voxels:.3g}, pre-int."
    return f"{choice.step_voxels:.3g}, refine {choice.refine}, {getattr(choice, 'refine_walk', 'even')}"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--target", type=float, default=5e-3)
    p.add_argument("--size", type=int, default=512)
    p.add_argument("--error-size", type=int, default=128)
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--scenes", default="ml,head,noise", help="comma-separated: ml, head, noise")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    lines = [f"`LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS', 'unset')} python scripts/narrow_spike_numbers.py"
             f" --target {args.target:g}` ({args.size}x{args.size} frames, median of {args.repeats} taken round "
             f"robin with VTK's one-voxel frame; RMSE against `reference.exact` at {args.error_size}x"
             f"{args.error_size})", "",
             "| scene | VTK 1 voxel: ms / RMSE | dvr_gl | step (voxel), sampling | ms | RMSE | time / VTK |",
             "|---|---|---|---|---|---|---|"]
    peer = VTKPeer()
    try:
        for name, volume, tf, camera in scenes(args.scenes.split(",")):
            big = dvr_gl.Scene(volume, tf, camera, args.size, args.size)
            small = big.replace(width=args.error_size, height=args.error_size)
            exact = reference.exact(small)
            h = volume.min_spacing
            # a renderer per setting: in one renderer the settings' tables push each other
            # out of its caches, and a round robin would time their rebuilding
            renderers = []
            try:
                rows = []       # (label, words, frame, rmse)
                gl = dvr_gl.Renderer()
                renderers.append(gl)
                got = metrics.rmse(gl.render(small, tolerance=args.target), exact)
                rows.append(("`tolerance=`", choice_words(gl.last_choice),
                             lambda gl=gl: gl.render(big, tolerance=args.target), got))
                gl = dvr_gl.Renderer()       # the step chosen for the walk by reach, asked for
                renderers.append(gl)
                got = metrics.rmse(gl.render(small, tolerance=args.target, **REACH), exact)
                rows.append(("`tolerance=`, reach asked", choice_words(gl.last_choice),
                             lambda gl=gl: gl.render(big, tolerance=args.target, **REACH), got))
                for way, opts in WAYS:
                    gl = dvr_gl.Renderer()
                    renderers.append(gl)
                    met = None
                    for k in LADDER:       # longest first
                        e = metrics.rmse(gl.render(small, step=k * h, **opts), exact)
                        if e <= args.target:
                            met = (k, e)
                            break
                    if met is not None:
                        k, e = met
                        rows.append(("fixed", words(k, way), lambda gl=gl, k=k, o=opts: gl.render(big, step=k * h, **o),
                                     e))
                    print(f"{name}: {way}: {met}", file=sys.stderr, flush=True)
                peer.setup(small, h)
                vtk_rmse = metrics.rmse(peer.frame(), exact)
                peer.setup(big, h)
                _, times = interleaved_frames([peer.frame] + [r[2] for r in rows], args.repeats)
                ms = [statistics.median(t) * 1e3 for t in times]
                for (label, w, _, e), t in zip(rows, ms[1:]):
                    lines.append(f"| {name} | {ms[0]:.0f} / {vtk_rmse:.2e} | {label} | {w} | {t:.0f} | {e:.2e} | "
                                 f"{t / ms[0]:.2f} |")
            finally:
                for gl in renderers:
                    gl.release()
    finally:
        peer.close()
    text = "\n".join(lines) + "\n"
    if args.out:
        atomic_write(args.out, text.encode())
    print(text)


if __name__ == "__main__":
    main()
