"""scenes/image_error.py: image error measures the comparison scripts share (oiiotool, Debian
openimageio-tools). Imported by volume_equal_time.py and guiding_benchmark.py."""
import re
import subprocess
import sys


def mse(a, b):
    """Mean squared error between the RGB channels of two EXRs (oiiotool --diff's RMS squared)."""
    r = subprocess.run(["oiiotool", a, "--ch", "R,G,B", b, "--ch", "R,G,B", "--diff"], capture_output=True, text=True)
    m = re.search(r"RMS error = ([0-9.eE+-]+)", r.stdout + r.stderr)
    if not m and r.returncode == 0 and "PASS" in r.stdout:
        return 0.0  # identical pixels: oiiotool prints no error figures
    if not m:
        sys.exit("oiiotool --diff gave no RMS error for %s %s:\n%s" % (a, b, r.stdout + r.stderr))
    return float(m.group(1)) ** 2
