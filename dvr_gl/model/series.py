"""A volume over time: :class:`VolumeSeries`, one :class:`~dvr_gl.model.volume.Volume`
per time step on one grid.

Every step shares the first one's shape, spacing, origin and anatomical orientation, so
that one camera frames them all and a picture of step 5 lies where the picture of step 0
does; a step that differs is a :class:`StepMismatchError` naming the step and what
differs. :attr:`VolumeSeries.data_range` covers every step, and
:meth:`VolumeSeries.pooled` is one volume holding every step's samples, for choosing a
transfer function once that fits every frame (presets read ranges and percentiles).

Files become series in :mod:`dvr_gl.formats.series`: a list of files or a glob pattern,
or one 4-D array."""

from __future__ import annotations

import numpy as np

from .volume import Volume


class StepMismatchError(ValueError):
    """A step of a :class:`VolumeSeries` that does not match the first: ``step`` is its
    index, ``field`` what differs (``shape``, ``spacing``, ``origin`` or
    ``orientation``), ``value`` its value and ``expected`` the first step's."""

    def __init__(self, step, field, value, expected, name=None):
        self.step, self.field, self.value, self.expected, self.name = step, field, value, expected, name
        where = f"step {step}" + (f" ({name})" if name else "")
        super().__init__(f"{where} has {field} {value}, but step 0 has {expected}: every step of a series "
                         f"shares the first one's shape, spacing, origin and orientation")


class VolumeSeries:
    """Volumes over time on one grid.

    Parameters
    ----------
    volumes : a non-empty sequence of :class:`dvr_gl.Volume`, one per time step, in order.
        They share shape, spacing, origin and orientation (a step that differs is a
        :class:`StepMismatchError`); sample types may differ.
    names : optional labels of the steps (such as the files they came from), one per
        step; error messages and :meth:`label` use them.

    ``len(series)`` is the number of steps, ``series[i]`` step ``i`` (a ``Volume``;
    negative indices count from the end, a slice gives a shorter series), and iterating
    gives the steps in order. The grid's ``shape``, ``spacing``, ``origin``, ``bounds``
    and ``orientation`` are the steps' own.
    """

    def __init__(self, volumes, names=None):
        if isinstance(volumes, Volume):
            raise TypeError("volumes must be a sequence of dvr_gl.Volume, one per time step, got a single Volume")
        try:
            volumes = tuple(volumes)
        except TypeError:
            raise TypeError(f"volumes must be a sequence of dvr_gl.Volume, got {type(volumes).__name__}") from None
        if not volumes:
            raise ValueError("volumes is empty: a VolumeSeries needs at least one time step")
        for i, v in enumerate(volumes):
            if not isinstance(v, Volume):
                raise TypeError(f"volumes[{i}] must be a dvr_gl.Volume, got {type(v).__name__}")
        if names is not None:
            names = tuple(str(n) for n in names)
            if len(names) != len(volumes):
                raise ValueError(f"names has {len(names)} entries for {len(volumes)} steps; give one per step")
        first = volumes[0]
        for i, v in enumerate(volumes[1:], start=1):
            name = names[i] if names is not None else None
            if v.shape != first.shape:
                raise StepMismatchError(i, "shape", tuple(v.shape), tuple(first.shape), name)
            for field in ("spacing", "origin"):
                mine, theirs = getattr(v, field), getattr(first, field)
                if not np.array_equal(mine, theirs):
                    raise StepMismatchError(i, field, tuple(mine.tolist()), tuple(theirs.tolist()), name)
            if v.orientation != first.orientation:
                raise StepMismatchError(i, "orientation", v.orientation, first.orientation, name)
        self.volumes = volumes
        self.names = names
        self.data_range = (min(v.data_range[0] for v in volumes), max(v.data_range[1] for v in volumes))
        self._pooled = None

    @classmethod
    def from_array(cls, array, spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0), mask_nonfinite=False,
                   orientation=None, modality=None):
        """A series from a 4-D array (nt, nz, ny, nx): time first, then each step laid out
        as a Volume's samples (z slowest, x fastest). The other arguments are each step's
        (see :class:`dvr_gl.Volume`)."""
        if not isinstance(array, np.ndarray):
            raise TypeError(f"array must be a numpy array (nt, nz, ny, nx), got {type(array).__name__}")
        if array.ndim != 4:
            raise ValueError(f"array must be 4-D (nt, nz, ny, nx), time first, got ndim={array.ndim} "
                             f"shape={array.shape}")
        if array.shape[0] < 1:
            raise ValueError(f"array has no time step (shape {array.shape}); a series needs at least one")
        return cls([Volume(step, spacing=spacing, origin=origin, mask_nonfinite=mask_nonfinite,
                           orientation=orientation, modality=modality) for step in array])

    # -- the steps ----------------------------------------------------------------
    def __len__(self):
        return len(self.volumes)

    def __getitem__(self, index):
        if isinstance(index, slice):
            names = None if self.names is None else self.names[index]
            return VolumeSeries(self.volumes[index], names)
        try:
            i = int(np.arange(len(self.volumes))[index])
        except (IndexError, TypeError):
            if isinstance(index, (int, np.integer)) and not isinstance(index, bool):
                raise IndexError(f"step {index} is outside this series of {len(self)} steps "
                                 f"(0..{len(self) - 1}, or negative from the end)") from None
            raise TypeError(f"a series is indexed by a step number or a slice, got {index!r}") from None
        return self.volumes[i]

    def __iter__(self):
        return iter(self.volumes)

    def label(self, step):
        """What to call step ``step``: its name where the series has names."""
        return self.names[step] if self.names is not None else f"step {step}"

    # -- the shared grid ----------------------------------------------------------------
    @property
    def shape(self):
        """(nz, ny, nx) of every step."""
        return self.volumes[0].shape

    @property
    def spacing(self):
        return self.volumes[0].spacing

    @property
    def origin(self):
        return self.volumes[0].origin

    @property
    def orientation(self):
        return self.volumes[0].orientation

    @property
    def modality(self):
        return self.volumes[0].modality

    @property
    def bounds(self):
        """(lower corner, upper corner) of the shared box in world units."""
        return self.volumes[0].bounds

    def pooled(self) -> Volume:
        """One Volume holding every step's samples, the steps stacked along z (made once
        and kept): what a transfer-function preset reads (the range, percentiles, the
        sample type, the smallest spacing, modality and orientation) over the whole
        series, so that one transfer function fits every frame. Its gradients across the
        seams between steps mean nothing: it is for classification, not for rendering."""
        if self._pooled is None:
            first = self.volumes[0]
            dtype = np.result_type(*(v.data.dtype for v in self.volumes))
            data = np.concatenate([v.data.astype(dtype, copy=False) for v in self.volumes], axis=0)
            self._pooled = Volume(data, spacing=first.spacing, origin=first.origin,
                                  mask_nonfinite=any(v.mask_nonfinite for v in self.volumes),
                                  orientation=first.orientation, modality=first.modality,
                                  orientation_assumed=first.orientation_assumed)
        return self._pooled

    def __repr__(self):
        lo, hi = self.data_range
        return (f"VolumeSeries({len(self)} steps, shape={self.shape}, spacing={tuple(self.spacing.tolist())}, "
                f"origin={tuple(self.origin.tolist())}, range=({lo!r}, {hi!r}))")
