"""Where a build folder keeps the mlfe command line: converters/cli/mlfe, or cli/mlfe in builds
made before the move to converters/ (a --base-build of an older checkout)."""
import os


def mlfe_binary(build):
    new = os.path.join(build, "converters", "cli", "mlfe")
    old = os.path.join(build, "cli", "mlfe")
    return old if not os.path.exists(new) and os.path.exists(old) else new
