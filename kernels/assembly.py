"""Race-free assembly: per-item force buffers gathered per node through a CSR map.

Elements write their corner forces to an (n_elements * 8, 3) buffer and contact points their five
node forces to an (n_contacts * 5, 3) buffer; each node then sums the rows that belong to it.
Every node is written by exactly one thread, so the result is deterministic.
"""
import numpy as np

from .config import ijit, pjit, prange


def node_row_map(items, n_nodes):
    """CSR map from nodes to the rows of a flattened per-item buffer.

    Parameters
    ----------
    items : (n_items, k) int64
        node ids of each item (hexahedron corners, contact nodes); entries < 0 are skipped.
    n_nodes : int

    Returns
    -------
    ptr : (n_nodes + 1,) int64, rows : (n_items * k,) int64
        rows ``rows[ptr[i]:ptr[i+1]]`` of the (n_items * k, 3) buffer belong to node i.
    """
    flat = np.asarray(items, dtype=np.int64).ravel()
    keep = np.nonzero(flat >= 0)[0]
    order = keep[np.argsort(flat[keep], kind="stable")]
    counts = np.bincount(flat[keep], minlength=n_nodes)
    ptr = np.zeros(n_nodes + 1, dtype=np.int64)
    np.cumsum(counts, out=ptr[1:])
    return ptr, order.astype(np.int64)


@ijit
def rows_sum(buf, ptr, rows, i):
    """Sum of the rows of ``buf`` (m, 3) that belong to node i (see :func:`node_row_map`)."""
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    for q in range(ptr[i], ptr[i + 1]):
        r = rows[q]
        a0 += buf[r, 0]
        a1 += buf[r, 1]
        a2 += buf[r, 2]
    return a0, a1, a2


@ijit
def gather_node(buf_a, ptr_a, rows_a, buf_b, ptr_b, rows_b, out, i):
    """``out[i]`` = node i's rows of ``buf_a`` plus its rows of ``buf_b``."""
    a0, a1, a2 = rows_sum(buf_a, ptr_a, rows_a, i)
    b0, b1, b2 = rows_sum(buf_b, ptr_b, rows_b, i)
    out[i, 0] = a0 + b0
    out[i, 1] = a1 + b1
    out[i, 2] = a2 + b2


@pjit
def gather_pair(buf_a, ptr_a, rows_a, buf_b, ptr_b, rows_b, out):
    """``out[i] = (node i's rows of buf_a) + (its rows of buf_b)`` in one pass (two maps of
    :func:`node_row_map`, e.g. hexahedra and contact points); out (n, 3) overwritten."""
    for i in prange(out.shape[0]):
        gather_node(buf_a, ptr_a, rows_a, buf_b, ptr_b, rows_b, out, i)
