"""Rendered images that show themselves: :class:`RenderedImage` is what
:func:`dvr_gl.render` returns, a float32 NumPy array (premultiplied RGBA, row 0 on top)
that Jupyter, through ``_repr_png_``, shows as a picture over its ``background``."""

from __future__ import annotations

import io as _io

import numpy as np

from .. import formats as dvr_io

#: the background a displayed image is composited over (white, as ``dvr-gl render``)
DEFAULT_BACKGROUND = (1.0, 1.0, 1.0)


def png_bytes(image, background=DEFAULT_BACKGROUND, compress_level=1):
    """PNG-encoded bytes of ``image`` ((H, W, 4) float premultiplied RGBA) composited over
    ``background`` (None: un-premultiplied RGBA), as :func:`dvr_gl.formats.save_png` writes it.
    A low zlib level: the widget sends a frame per drag step."""
    from PIL import Image
    buffer = _io.BytesIO()
    Image.fromarray(dvr_io.to_png_array(image, background)).save(buffer, format="PNG",
                                                                 compress_level=compress_level)
    return buffer.getvalue()


class RenderedImage(np.ndarray):
    """A rendered image ((H, W, 4) float premultiplied RGBA) that Jupyter displays as a
    picture over ``background``. It is a NumPy array in every other respect; an array
    derived from it that is not an image (a channel, a mean) displays as numbers."""

    def __new__(cls, image, background=DEFAULT_BACKGROUND):
        obj = np.asarray(image).view(cls)
        obj.background = background
        return obj

    def __array_finalize__(self, obj):
        self.background = getattr(obj, "background", DEFAULT_BACKGROUND)

    def __array_wrap__(self, array, context=None, return_scalar=False):
        # ufunc results that are no longer an image (a mean, a channel) are plain arrays
        if array.ndim == 3 and array.shape[2] == 4:
            return RenderedImage(array, self.background)     # NumPy 1 and 2 alike
        plain = np.asarray(array).view(np.ndarray)
        return plain[()] if return_scalar or plain.ndim == 0 else plain

    def _repr_png_(self):
        if self.ndim != 3 or self.shape[2] != 4 or self.dtype.kind != "f" or min(self.shape[:2]) < 1:
            return None            # not an image: IPython falls back to the text form
        return png_bytes(np.asarray(self), self.background)
