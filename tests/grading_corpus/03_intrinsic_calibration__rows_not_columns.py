# Corpus of plausible student mistakes for tests/test_grading.py (also test_selfcheck_diagnosis.py).
# mistake: rows_not_columns
# expect: built from the rows of H

import numpy as np


def intrinsic_constraints(H):
    H = np.asarray(H, dtype=float)

    def v(i, j):
        hi, hj = H[i, :], H[j, :]
        return np.array([hi[0] * hj[0], hi[0] * hj[1] + hi[1] * hj[0], hi[1] * hj[1],
                         hi[2] * hj[0] + hi[0] * hj[2], hi[2] * hj[1] + hi[1] * hj[2], hi[2] * hj[2]])

    return np.vstack([v(0, 1), v(0, 0) - v(1, 1)])
