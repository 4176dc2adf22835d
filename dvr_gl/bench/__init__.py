"""Benchmarks of dvr_gl's techniques (``dvr-gl bench``) and VTK as a peer renderer.

Nothing on the runtime path imports this package: rendering, the references and the
front ends work without it, and VTK (the ``bench`` extra) is needed only here.

- ``cli``: the ``dvr-gl bench`` options and the dispatch over the suites;
- one module per suite: ``raycast`` (the ray caster beside VTK, the default suite),
  ``slicing``, ``mesh``, ``particles``, ``shading`` and ``all`` (every technique, one
  report);
- ``common``: what the suites share (data sets, cameras, timing, machine info, output);
- ``vtk_peer``: the same scene rendered by VTK, for the suites to compare against.

Imports point one way: ``cli`` imports the suites, the suites import ``common`` and
``vtk_peer``, and neither of those imports a suite.
"""
