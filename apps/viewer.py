"""Open a volume in the interactive viewer (the same as ``dvr-gl view``).

    python apps/viewer.py builtin:ct_head --elevation 90
    python apps/viewer.py scan.nrrd --tf bone.json --technique raycast

Press h in the window for the keys. You should see the volume with the transfer-function
editor along the bottom of the window."""

import sys

from dvr_gl.frontends.viewer import main

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
