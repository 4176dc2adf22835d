"""glfw's key, button and action codes, and the list of what each key does.

The codes are stable parts of glfw's API, copied here so that the input handlers (and
tests that drive them with synthetic events) need no glfw import.
"""

PRESS, RELEASE, REPEAT = 1, 0, 2
MOUSE_LEFT, MOUSE_RIGHT, MOUSE_MIDDLE = 0, 1, 2
MOD_SHIFT, MOD_CONTROL, MOD_ALT, MOD_SUPER = 0x1, 0x2, 0x4, 0x8
KEY_ESCAPE, KEY_F1 = 256, 290
KEY_F2, KEY_F3, KEY_F4, KEY_F5 = 291, 292, 293, 294
KEY_MINUS, KEY_EQUAL, KEY_COMMA, KEY_PERIOD = 45, 61, 44, 46
KEY_LEFT_BRACKET, KEY_RIGHT_BRACKET = 91, 93
KEY_KP_SUBTRACT, KEY_KP_ADD = 333, 334


# keys that act again while held down (the others act once per press)
REPEATABLE = {KEY_MINUS, KEY_EQUAL, KEY_COMMA, KEY_PERIOD, KEY_LEFT_BRACKET, KEY_RIGHT_BRACKET,
              KEY_KP_SUBTRACT, KEY_KP_ADD}


def key_code(char):
    """glfw's code of a letter or digit key (its upper-case ASCII code)."""
    return ord(char.upper())


KEYS_HELP = """\
dvr-gl view: keys and mouse
  left drag            orbit (trackball: no flip over the poles)
  right drag, wheel    zoom
  middle / shift drag  pan
  ctrl + left drag     window/level of the transfer function (x: level, y: width)
  alt + left drag      move the clip plane along its normal (up: along it)
  double click         recentre on the point under the cursor (on nothing: the volume centre)
  r                    reset the view
  t / T                next / previous technique (those that can render this data)
  m / M                next / previous mode (composite, mip, minip, average, isosurface)
  , / .                iso value down / up (isosurface mode; shift: 5x)
  l                    shading on / off (on at the start where the technique lights samples)
  x                    optical model: emission-absorption, absorption only, emission only, Sabella
  i                    illustration: none, boundary, silhouette, tone, depth cue, all four
  p                    pre-integration on / off (techniques that offer it)
  c                    cell order mpvo / centroid / walk (tetra, for meshes)
  k / K                clip plane through the centre facing you, on / off; turn it to face you
  g                    show / hide the surfaces given with --geometry
  F2 F3 F4 F5          show / hide volume 1..4: INPUT (or its first channel), then each
                       --volume, then --labels (or the other --channels)
  - / =                coarser / finer step (slice2d: fewer / more interpolated slices;
                       tetra: none, each cell is integrated exactly; raycast with
                       --tolerance: twice / half the tolerance)
  1..9                 transfer function: 1 the one given, then the presets
  [ / ]                opacity scale down / up
  e                    show / hide the transfer-function editor
  o                    orthographic / perspective
  b                    cycle the background colour
  s / S                save a screenshot: the render (no overlay) / the window as shown
  ctrl+s / ctrl+o      save / load the transfer function (JSON for dvr-gl render --tf)
  h, F1                print this list
  q, Esc               quit
transfer-function editor (bottom panel)
  left click / drag    add / move a control point (opacity curve above, colours below)
  right click          remove a control point
  wheel on a colour    turn its hue"""
