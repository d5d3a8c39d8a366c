#!/usr/bin/python3
"""mrcal's own projection uncertainty of a .cameramodel procam wrote (its optimization_inputs).

Usage: projection_uncertainty_mrcal.py MODEL DISTANCE_M X,Y [X,Y ...]

Prints one JSON object: sigma (mrcal's estimate of the corner noise, px), and per pixel the
worst-direction standard deviation at infinity and at DISTANCE_M along the pixel's ray (px),
with the 2x2 covariance at infinity, all from mrcal.projection_uncertainty. Also re-runs
mrcal.optimize on a copy of the inputs and reports how far the solve moved (0 when procam's
inputs are at mrcal's optimum). The projection_uncertainty test compares procam's numbers with
these.
"""
import copy
import json
import sys

import numpy as np
import mrcal


def main():
    model = mrcal.cameramodel(sys.argv[1])
    distance = float(sys.argv[2])
    pixels = np.array([[float(v) for v in arg.split(",")] for arg in sys.argv[3:]])
    inputs = model.optimization_inputs()
    directions = mrcal.unproject(pixels, *model.intrinsics(), normalize=True)
    at_infinity = mrcal.projection_uncertainty(directions, model=model, atinfinity=True,
                                               what="worstdirection-stdev")
    at_distance = mrcal.projection_uncertainty(directions * distance, model=model,
                                               atinfinity=False, what="worstdirection-stdev")
    covariance = mrcal.projection_uncertainty(directions, model=model, atinfinity=True,
                                              what="covariance")
    sigma = np.std(mrcal.residuals_chessboard(inputs).ravel())

    resolved = copy.deepcopy(inputs)
    mrcal.optimize(**resolved)
    moved_intrinsics = np.max(np.abs(resolved["intrinsics"] - inputs["intrinsics"]))

    print(json.dumps({
        "sigma": float(sigma),
        "at_infinity": at_infinity.tolist(),
        "at_distance": at_distance.tolist(),
        "covariance_at_infinity": covariance.tolist(),
        "resolve_moved_intrinsics": float(moved_intrinsics),
    }))


if __name__ == "__main__":
    main()
