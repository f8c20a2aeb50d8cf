"""Binary-image morphology the detector is built on: connected components and dilation (pure
numpy, no OpenCV: the loops run over runs of pixels or over the radius, never over pixels).
"""
from __future__ import annotations

from typing import Tuple

import numpy as np


def label_components(mask: np.ndarray) -> Tuple[np.ndarray, int]:
    """8-connected components of a boolean image: labels (H, W) int32 (0 = background, 1..n)
    and n. Runs of each row are joined with the overlapping runs of the row above (union-find
    over runs: the loop is over runs, not pixels).

    :param mask: (H, W) bool.
    """
    height, width = mask.shape
    padded = np.zeros((height, width + 2), dtype=np.int8)
    padded[:, 1:-1] = mask
    edges = np.diff(padded, axis=1)
    rows_s, starts = np.nonzero(edges == 1)
    _, ends = np.nonzero(edges == -1)  # exclusive; same order as the starts (row-major)
    count = len(starts)
    labels = np.zeros((height, width), dtype=np.int32)
    if count == 0:
        return labels, 0
    parent = list(range(count))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    row_first = np.searchsorted(rows_s, np.arange(height + 1))
    rows_l, starts_l, ends_l = rows_s.tolist(), starts.tolist(), ends.tolist()
    for i in range(count):
        row = rows_l[i]
        if row == 0:
            continue
        for j in range(row_first[row - 1], row_first[row]):
            # 8-connected: runs touch if they overlap once widened by one pixel.
            if starts_l[j] <= ends_l[i] and starts_l[i] <= ends_l[j]:
                a, b = find(i), find(j)
                if a != b:
                    parent[max(a, b)] = min(a, b)
    roots = np.array([find(i) for i in range(count)])
    _, compact = np.unique(roots, return_inverse=True)
    for i in range(count):
        labels[rows_l[i], starts_l[i]:ends_l[i]] = compact[i] + 1
    return labels, int(compact.max()) + 1


def dilate(mask: np.ndarray, pixels: int) -> np.ndarray:
    """``mask`` grown by ``pixels`` (a square neighbourhood).

    :param mask: (H, W) bool.
    :param pixels: how far to grow (pixels); 0 gives a copy.
    """
    grown = mask.copy()
    for _ in range(pixels):
        step = grown.copy()
        step[1:, :] |= grown[:-1, :]
        step[:-1, :] |= grown[1:, :]
        step[:, 1:] |= grown[:, :-1]
        step[:, :-1] |= grown[:, 1:]
        grown = step
    return grown
