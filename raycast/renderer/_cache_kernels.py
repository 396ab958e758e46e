"""Compiled (numba) loops of the fast path (raycast.renderer.cache), where numpy needed (elements, frames) arrays.

* Bit-held elements: their visibility bits are held as (directions, words) uint64, element ``e``
  at bit ``e % 64`` of word ``e // 64``. For each frame the four cube-map nodes around the Sun
  and the four around the observer are ANDed (visible at all of them) and ORed (at any) one
  word at a time; :func:`mixed_pairs` returns the pairs where the eight differ, for exact rays
  (:func:`pair_rays`, :func:`open_fraction`). Only the set bits are read.
* Shading classes (:func:`lit_classes`): one frame at a time, each group's lit-and-seen area
  (exposed, agreed bits, the mixed pairs' open fractions, factorised visibility), gated by its
  geometric normal and summed into its class with its normals; only the classes with light
  are returned, so nothing of size (frames, groups) or (frames, classes) is held. Elements
  come in group order: in a word whose every byte holds elements of one group, each byte's set
  bits add their area from a table of its 256 values (:func:`byte_areas`) in one read.
"""

import math

from numba import njit
from numba.cpython.unsafe.numbers import trailing_zeros
import numpy as np

from raycast.renderer.rays import SUN_RADIUS_SINE, risen_sun, sun_fraction


def pack_words(bits):
    """(d, e) bool -> (d, ceil(e / 64)) uint64, element e at bit e % 64 of word e // 64."""
    packed = np.packbits(bits, axis=1, bitorder="little")
    padded = np.zeros((packed.shape[0], -(-packed.shape[1] // 8) * 8), dtype=np.uint8)
    padded[:, : packed.shape[1]] = packed
    return np.ascontiguousarray(padded).view("<u8")


@njit(cache=True, nogil=True)
def _lowest_bit(word):
    """Index of the lowest set bit of a nonzero uint64: the processor's count of trailing zeros
    (half the time of lit_classes' loop over set bits against a De Bruijn table lookup)."""
    return trailing_zeros(word)


def mixed_pairs(words, sun_nodes, obs_nodes, sun, obs, normals):
    """The (frame, element) pairs whose bits differ among the eight nodes, to decide by rays.

    Parameters
    ----------
    words : (d, w) uint64 visibility bits.
    sun_nodes, obs_nodes : (m, 4) int64, the cube-map nodes around each frame's directions.
    sun, obs : (m, 3) float32 exact directions; normals : (e, 3) float32 element normals.

    Returns
    -------
    frames, elements : (p,) int64, in frame order, pairs visible at some node of both but not
        at all eight, and facing both exact directions.
    need : (p,) uint8, bit 0: the Sun's four nodes differ (cast toward the Sun), bit 1: the
        observer's do.
    """
    # A first guess: a thirty-second of all pairs (1% is usual).
    capacity = max(4096, len(sun_nodes) * len(normals) // 32)
    return _collected(_mixed_pairs, capacity, words, sun_nodes, obs_nodes, sun, obs, normals)


def _collected(kernel, capacity, *arguments):
    """``kernel(*arguments, frames, elements, need)``'s pairs (:func:`collected`)."""
    return collected(kernel, capacity, (np.int64, np.int64, np.uint8), *arguments)


def collected(kernel, capacity, dtypes, *arguments):
    """``kernel(*arguments, *outputs)``'s rows, one output array of each of ``dtypes``, sized
    `capacity` first; when they overflow (the kernel returns how many rows there were), it runs
    again with room for all. Returns views of the arrays' first rows."""
    while True:
        outputs = tuple(np.empty(capacity, dtype=dtype) for dtype in dtypes)
        count = kernel(*arguments, *outputs)
        if count <= capacity:
            return tuple(output[:count] for output in outputs)
        capacity = count


@njit(cache=True, nogil=True)
def _mixed_pairs(words, sun_nodes, obs_nodes, sun, obs, normals, frames, elements, need):
    # The pair arrays come in full size: growing them inside the loop made it three times slower.
    m, n_words = sun_nodes.shape[0], words.shape[1]
    count = 0
    zero = np.uint64(0)
    for f in range(m):
        s0, s1, s2, s3 = sun_nodes[f, 0], sun_nodes[f, 1], sun_nodes[f, 2], sun_nodes[f, 3]
        o0, o1, o2, o3 = obs_nodes[f, 0], obs_nodes[f, 1], obs_nodes[f, 2], obs_nodes[f, 3]
        sx, sy, sz = sun[f, 0], sun[f, 1], sun[f, 2]
        ox, oy, oz = obs[f, 0], obs[f, 1], obs[f, 2]
        for w in range(n_words):
            a, b, c, d = words[s0, w], words[s1, w], words[s2, w], words[s3, w]
            sun_all, sun_any = a & b & c & d, a | b | c | d
            a, b, c, d = words[o0, w], words[o1, w], words[o2, w], words[o3, w]
            obs_all, obs_any = a & b & c & d, a | b | c | d
            mixed = sun_any & obs_any & ~(sun_all & obs_all)
            if mixed != zero:
                count = _add_pairs(
                    mixed, w, sun_all, obs_all, f, sx, sy, sz, ox, oy, oz, normals, frames, elements, need, count
                )
    return count


@njit(cache=True, nogil=True, inline="always")
def _add_pairs(chosen, w, sun_all, obs_all, f, sx, sy, sz, ox, oy, oz, normals, frames, elements, need, count):
    """Append frame f's pairs with the elements of word w set in `chosen` that face both exact
    directions; `need` says which of their nodes differ (see :func:`mixed_pairs`). Past the
    arrays' capacity pairs are only counted. Returns the new count."""
    zero, one = np.uint64(0), np.uint64(1)
    capacity = len(frames)
    base = 64 * w
    while chosen != zero:
        bit = _lowest_bit(chosen)
        chosen &= chosen - one
        e = base + bit
        nx, ny, nz = normals[e, 0], normals[e, 1], normals[e, 2]
        if nx * sx + ny * sy + nz * sz <= -SUN_RADIUS_SINE or nx * ox + ny * oy + nz * oz <= 0.0:
            continue
        if count < capacity:
            shift = np.uint64(bit)
            frames[count] = f
            elements[count] = e
            need[count] = (((sun_all >> shift) & one) ^ one) | ((((obs_all >> shift) & one) ^ one) << one)
        count += 1
    return count


@njit(cache=True, nogil=True)
def merged_by_frame(first, second):
    """Two (frames, elements, need) triples, each in frame order, as one in frame order: each
    frame's pairs of ``first``, then its pairs of ``second`` (a stable sort of the two joined,
    in one pass)."""
    frames_a, elements_a, need_a = first
    frames_b, elements_b, need_b = second
    n_a, n_b = len(frames_a), len(frames_b)
    frames = np.empty(n_a + n_b, dtype=frames_a.dtype)
    elements = np.empty(n_a + n_b, dtype=elements_a.dtype)
    need = np.empty(n_a + n_b, dtype=need_a.dtype)
    i = j = k = 0
    while i < n_a or j < n_b:
        # A frame's run of each, in turn (runs, not pairs: the branch is taken once a run).
        f = min(frames_a[i] if i < n_a else frames_b[j], frames_b[j] if j < n_b else frames_a[i])
        while i < n_a and frames_a[i] == f:
            frames[k], elements[k], need[k] = f, elements_a[i], need_a[i]
            i += 1
            k += 1
        while j < n_b and frames_b[j] == f:
            frames[k], elements[k], need[k] = f, elements_b[j], need_b[j]
            j += 1
            k += 1
    return frames, elements, need


def gap_pairs(words, gap_ptr, gap_word, gap_mask, sun_nodes, obs_nodes, sun, obs, normals):
    """The (frame, element) pairs that may see through a gap narrower than the grid, to decide by rays.

    A node of an element's gap table (``gap_ptr``/``gap_word``/``gap_mask``: CSR by node of
    (word, bit mask) of bit-held elements; built by ``raycast.renderer.cache._horizon_gaps``) is
    blocked in the bits, close above the element's horizon, and has an open direction within
    half a grid spacing of it. A pair whose four nodes around the Sun (or the observer) are all
    blocked counts dark in :func:`mixed_pairs`; where one of those nodes is a gap node and the
    other side is seen (or lit, or a gap node too) at some node, rays toward the exact
    directions decide. Disjoint from :func:`mixed_pairs` (which needs both sides set at some
    node) and from the whole pairs (all eight set).

    Returns frames, elements, need as :func:`mixed_pairs`, in frame order.
    """
    return _collected(_gap_pairs, 4096, words, gap_ptr, gap_word, gap_mask, sun_nodes, obs_nodes, sun, obs, normals)


@njit(cache=True, nogil=True)
def _gap_pairs(words, gap_ptr, gap_word, gap_mask, sun_nodes, obs_nodes, sun, obs, normals, frames, elements, need):
    m, n_words = sun_nodes.shape[0], words.shape[1]
    count = 0
    zero = np.uint64(0)
    sun_gap = np.zeros(n_words, dtype=np.uint64)
    obs_gap = np.zeros(n_words, dtype=np.uint64)
    touched = np.empty(max(1, n_words), dtype=np.int64)
    for f in range(m):
        n_touched = 0
        for side in range(2):
            for j in range(4):
                node = sun_nodes[f, j] if side == 0 else obs_nodes[f, j]
                for k in range(gap_ptr[node], gap_ptr[node + 1]):
                    w = gap_word[k]
                    if sun_gap[w] == zero and obs_gap[w] == zero:
                        touched[n_touched] = w
                        n_touched += 1
                    if side == 0:
                        sun_gap[w] |= gap_mask[k]
                    else:
                        obs_gap[w] |= gap_mask[k]
        if n_touched == 0:
            continue
        s0, s1, s2, s3 = sun_nodes[f, 0], sun_nodes[f, 1], sun_nodes[f, 2], sun_nodes[f, 3]
        o0, o1, o2, o3 = obs_nodes[f, 0], obs_nodes[f, 1], obs_nodes[f, 2], obs_nodes[f, 3]
        sx, sy, sz = sun[f, 0], sun[f, 1], sun[f, 2]
        ox, oy, oz = obs[f, 0], obs[f, 1], obs[f, 2]
        for t in range(n_touched):
            w = touched[t]
            a, b, c, d = words[s0, w], words[s1, w], words[s2, w], words[s3, w]
            sun_all, sun_any = a & b & c & d, a | b | c | d
            a, b, c, d = words[o0, w], words[o1, w], words[o2, w], words[o3, w]
            obs_all, obs_any = a & b & c & d, a | b | c | d
            gaps = (sun_any | sun_gap[w]) & (obs_any | obs_gap[w]) & ~(sun_any & obs_any)
            sun_gap[w], obs_gap[w] = zero, zero
            count = _add_pairs(
                gaps, w, sun_all, obs_all, f, sx, sy, sz, ox, oy, oz, normals, frames, elements, need, count
            )
    return count


@njit(cache=True, nogil=True)
def byte_areas(ptr, group, area, n_words):
    """Tables for :func:`lit_classes`: each byte of bit-held elements (8 at a time, byte
    ``8 * w + b`` holding bits ``8 b .. 8 b + 7`` of word ``w``) whose pieces all lie in one group.

    Returns
    -------
    byte_slot : (8 w,) int32, the byte's row of ``byte_area``, or -1 where its elements' pieces
        lie in more than one group (or where it holds none).
    byte_group : (8 w,) int64, that one group.
    byte_area : (s, 256) float32, row s: the area of the byte's elements set in each value of it.
    """
    n_elements, n_bytes = len(ptr) - 1, 8 * n_words
    byte_slot = np.full(n_bytes, -1, dtype=np.int32)
    byte_group = np.zeros(n_bytes, dtype=np.int64)
    element_area = np.zeros(8)
    rows = 0
    for b in range(n_bytes):
        first, end = min(8 * b, n_elements), min(8 * b + 8, n_elements)
        if ptr[first] == ptr[end]:
            continue
        one_group = True
        for k in range(ptr[first], ptr[end]):
            one_group = one_group and group[k] == group[ptr[first]]
        if one_group:
            byte_slot[b], byte_group[b] = rows, group[ptr[first]]
            rows += 1
    byte_area = np.zeros((rows, 256), dtype=np.float32)
    for b in range(n_bytes):
        slot = byte_slot[b]
        if slot < 0:
            continue
        for i in range(8):
            e = 8 * b + i
            element_area[i] = 0.0
            if e < n_elements:
                for k in range(ptr[e], ptr[e + 1]):
                    element_area[i] += area[k]
        for value in range(1, 256):
            low = value & -value  # the value's lowest bit, added to the value without it
            byte_area[slot, value] = byte_area[slot, value ^ low] + element_area[_lowest_bit(np.uint64(low))]
    return byte_slot, byte_group, byte_area


class RowBuffers:
    """Output arrays :func:`lit_classes` writes its rows into and keeps for the next call (one
    per thread). Fresh arrays of a light curve's rows (tens of MB on a glossy mesh), grown as
    they filled, cost a fifth of the call in copies and page faults."""

    def __init__(self, capacity=1024):
        self.arrays = (
            np.empty(capacity, dtype=np.int64),
            np.empty(capacity, dtype=np.int64),
            np.empty(capacity),
            np.empty((capacity, 3)),
            np.empty((capacity, 3)),
        )


def lit_classes(*arguments, rows=None):
    """:func:`_lit_classes` with its output in ``rows`` (a :class:`RowBuffers`; new ones by
    default). The arrays returned are views of those buffers, valid until their next use."""
    rows = RowBuffers() if rows is None else rows
    count, *arrays = _lit_classes(*arguments, *rows.arrays)
    rows.arrays = tuple(arrays)
    return tuple(a[:count] for a in arrays)


@njit(cache=True, nogil=True)
def _lit_classes(
    words,
    sun_nodes,
    obs_nodes,
    ptr,
    group,
    area,
    byte_slot,
    byte_group,
    byte_area,
    pair_frames,
    pair_elements,
    pair_open,
    area_exposed,
    extra_weight,
    extra_groups,
    normal_geo,
    normal_shade,
    group_class,
    sun,
    obs,
    n_classes,
    class_normal,
    class_material,
    coarse_cos,
    class_target,
    n_targets,
    out_frames,
    out_classes,
    out_area,
    out_normal,
    out_geo,
):
    """Each frame's shading classes with light: their lit, seen and projected area and normals.

    A group's lit-and-seen area in a frame is its exposed area, plus its bit-held elements'
    pieces where all eight nodes agree (``words``, ``sun_nodes``, ``obs_nodes``; ``ptr``,
    ``group``, ``area`` CSC-style as in :func:`mixed_pairs`; ``byte_slot``, ``byte_group``,
    ``byte_area`` from :func:`byte_areas`), plus ``pair_open`` times the
    pieces of the mixed pairs (``pair_frames`` in frame order, ``pair_elements``), plus
    ``extra_weight`` (m, k) on ``extra_groups`` (k,) (the factorised groups). It is gated by
    the group's geometric normal (max(n_geo . obs, 0) and the part of the solar disk above its
    plane, :func:`raycast.renderer.rays.sun_fraction`) and summed into the group's class with
    the group's shading and geometric normals. One frame at a time, so no (frames, groups)
    array is held; ``group_class`` must be sorted (each class's groups in one run). Only the
    groups with area in the frame are visited: the exposed ones and those the frame's bits,
    pairs or factors touched (a bitmap of groups; the all-Glossy paper mesh has 138 625 groups
    and a frame lights a fraction of them).

    A class far from the frame's half vector is summed into a coarser one instead (its level
    ``l`` is the number of ``coarse_cos[class_material[c]]`` above the cosine of its nominal
    ``class_normal`` to the half vector, its coarse class ``class_target[l - 1, c]``; numbers
    from ``n_classes`` up to ``n_targets``), which is shaded once for all of them
    (``raycast.renderer.cache._coarse_classes``).

    Rows are written into ``out_*`` (grown where they fill).

    Returns
    -------
    count : int, the rows written; then the output arrays (new ones where they grew):
    frames, classes : (k,) int64, the (frame, class) pairs with light, in frame order; a
        coarse class's number is its target's.
    area : (k,) float64, the class's gated area.
    normal, geo : (k, 3) float64, its groups' shading and geometric normals weighted by their
        gated areas, normalised.
    """
    m, n_words = sun_nodes.shape[0], words.shape[1]
    n_groups = len(area_exposed)
    weight = np.zeros(n_groups)
    capacity = len(out_frames)
    out = (out_frames, out_classes, out_area, out_normal, out_geo)
    count = 0
    zero, one = np.uint64(0), np.uint64(1)
    n_levels = class_target.shape[0]
    # Coarse classes' sums this frame (total, shading normal, geometric normal), and which have any.
    coarse = np.zeros((max(n_targets - n_classes, 0), 7))  # coarse class t at row t - n_classes
    coarse_used = np.empty(max(n_targets - n_classes, 0), dtype=np.int64)
    # Groups with area this frame, a bit each: the exposed ones always, the others as touched.
    n_group_words = (n_groups + 63) // 64
    exposed = np.zeros(n_group_words, dtype=np.uint64)
    for g in range(n_groups):
        if area_exposed[g] != 0.0:
            exposed[g >> 6] |= one << np.uint64(g & 63)
    touched = exposed.copy()
    # Words read byte by byte: those whose every byte lies in one group (the last word's bytes
    # past the elements have no bits set, so their slot -1 is never read).
    by_bytes = np.ones(n_words, dtype=np.bool_)
    for b in range(8 * n_words):
        if byte_slot[b] < 0 and 8 * b < len(ptr) - 1:
            by_bytes[b // 8] = False
    pair = 0
    run_group, run_area = 0, 0.0
    for f in range(m):
        s0, s1, s2, s3 = sun_nodes[f, 0], sun_nodes[f, 1], sun_nodes[f, 2], sun_nodes[f, 3]
        o0, o1, o2, o3 = obs_nodes[f, 0], obs_nodes[f, 1], obs_nodes[f, 2], obs_nodes[f, 3]
        for w in range(n_words):
            both = (
                words[s0, w]
                & words[s1, w]
                & words[s2, w]
                & words[s3, w]
                & words[o0, w]
                & words[o1, w]
                & words[o2, w]
                & words[o3, w]
            )
            if both == zero:
                continue
            # Elements come in group order: a run of one group's pieces is summed in a register
            # (adding each to memory waits on the previous add to the same group).
            if not by_bytes[w]:
                while both != zero:
                    e = 64 * w + _lowest_bit(both)
                    both &= both - one
                    for k in range(ptr[e], ptr[e + 1]):
                        if group[k] == run_group:
                            run_area += area[k]
                        else:
                            weight[run_group] += run_area
                            touched[run_group >> 6] |= one << np.uint64(run_group & 63)
                            run_group, run_area = group[k], area[k]
                continue
            # A word whose every byte lies in one group: each byte's set bits add their area
            # from its table in one read.
            for b in range(8):
                byte = (both >> np.uint64(8 * b)) & np.uint64(255)
                if byte == zero:
                    continue
                g, value = byte_group[8 * w + b], byte_area[byte_slot[8 * w + b], byte]
                if g == run_group:
                    run_area += value
                else:
                    weight[run_group] += run_area
                    touched[run_group >> 6] |= one << np.uint64(run_group & 63)
                    run_group, run_area = g, value
        if run_area != 0.0:
            weight[run_group] += run_area
            touched[run_group >> 6] |= one << np.uint64(run_group & 63)
        run_group, run_area = 0, 0.0
        while pair < len(pair_frames) and pair_frames[pair] == f:
            value = pair_open[pair]
            if value != 0.0:
                e = pair_elements[pair]
                for k in range(ptr[e], ptr[e + 1]):
                    g = group[k]
                    weight[g] += value * area[k]
                    touched[g >> 6] |= one << np.uint64(g & 63)
            pair += 1
        for j in range(len(extra_groups)):
            g = extra_groups[j]
            weight[g] += extra_weight[f, j]
            touched[g >> 6] |= one << np.uint64(g & 63)
        if count + n_classes > capacity:
            capacity = max(2 * capacity, count + n_classes)
            out_frames = grown(out_frames, capacity, count)
            out_classes = grown(out_classes, capacity, count)
            out_area = grown(out_area, capacity, count)
            out_normal = grown(out_normal, capacity, count)
            out_geo = grown(out_geo, capacity, count)
            out = (out_frames, out_classes, out_area, out_normal, out_geo)
        sx, sy, sz = sun[f, 0], sun[f, 1], sun[f, 2]
        ox, oy, oz = obs[f, 0], obs[f, 1], obs[f, 2]
        hx, hy, hz = sx + ox, sy + oy, sz + oz
        h_norm = math.sqrt(hx * hx + hy * hy + hz * hz)
        # Backlit to within 1e-6: no half vector, every class at its own level.
        levels = n_levels if h_norm > 1e-6 else 0
        if levels:
            hx, hy, hz = hx / h_norm, hy / h_norm, hz / h_norm
        n_used = 0
        # Groups come sorted by class (SceneCache.build): each class is summed in one run.
        current = -1
        total, nx, ny, nz, gx_sum, gy_sum, gz_sum = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        word, bits = 0, touched[0] if n_group_words else zero
        while True:
            # The next group with area, in order (n_groups past the last: flushes the last class).
            while bits == zero and word + 1 < n_group_words:
                touched[word] = exposed[word]
                word += 1
                bits = touched[word]
            if bits == zero:
                if n_group_words:
                    touched[word] = exposed[word]
                g = n_groups
            else:
                g = 64 * word + _lowest_bit(bits)
                bits &= bits - one
            c = group_class[g] if g < n_groups else -2
            if c != current:
                if total > 0.0:
                    level = 0
                    if levels:
                        cos_h = (
                            class_normal[current, 0] * hx
                            + class_normal[current, 1] * hy
                            + class_normal[current, 2] * hz
                        )
                        material = class_material[current]
                        while level < levels and cos_h < coarse_cos[material, level]:
                            level += 1
                    if level == 0:
                        _put_row(
                            out,
                            count,
                            f,
                            current,
                            total,
                            nx,
                            ny,
                            nz,
                            gx_sum,
                            gy_sum,
                            gz_sum,
                        )
                        count += 1
                    else:
                        t = class_target[level - 1, current] - n_classes
                        if coarse[t, 0] == 0.0:
                            coarse_used[n_used] = t
                            n_used += 1
                        coarse[t, 0] += total
                        coarse[t, 1] += nx
                        coarse[t, 2] += ny
                        coarse[t, 3] += nz
                        coarse[t, 4] += gx_sum
                        coarse[t, 5] += gy_sum
                        coarse[t, 6] += gz_sum
                current = c
                total, nx, ny, nz, gx_sum, gy_sum, gz_sum = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
            if g == n_groups:
                break
            # A lit-and-seen area is never negative; the factors' float32 rounding can make it -1e-7.
            w = area_exposed[g] + weight[g]
            weight[g] = 0.0
            if w <= 0.0:
                continue
            gx, gy, gz = normal_geo[g, 0], normal_geo[g, 1], normal_geo[g, 2]
            cos_o = gx * ox + gy * oy + gz * oz
            cos_s = gx * sx + gy * sy + gz * sz
            if cos_o <= 0.0 or cos_s <= -SUN_RADIUS_SINE:
                continue
            w *= cos_o * sun_fraction(cos_s)
            total += w
            nx += w * normal_shade[g, 0]
            ny += w * normal_shade[g, 1]
            nz += w * normal_shade[g, 2]
            gx_sum += w * gx
            gy_sum += w * gy
            gz_sum += w * gz
        for i in range(n_used):
            # Indexed, not through a row view: views (reference-counted) took 1.5 of the 21.5 ms
            # of a call on the all-Glossy paper mesh.
            t = coarse_used[i]
            _put_row(
                out,
                count,
                f,
                n_classes + t,
                coarse[t, 0],
                coarse[t, 1],
                coarse[t, 2],
                coarse[t, 3],
                coarse[t, 4],
                coarse[t, 5],
                coarse[t, 6],
            )
            count += 1
            for k in range(7):
                coarse[t, k] = 0.0
    return count, out_frames, out_classes, out_area, out_normal, out_geo


@njit(cache=True, nogil=True, inline="always")
def _put_row(out, row, f, c, total, nx, ny, nz, gx, gy, gz):
    """Row ``row`` of :func:`lit_classes`' output ``out`` (frames, classes, area, normal, geo):
    frame f's class c, its gated area and its area-weighted normal sums, normalised."""
    frames, classes, area, normal, geo = out
    norm = math.sqrt(nx * nx + ny * ny + nz * nz)
    geo_norm = math.sqrt(gx * gx + gy * gy + gz * gz)
    frames[row], classes[row], area[row] = f, c, total
    normal[row, 0], normal[row, 1], normal[row, 2] = nx / norm, ny / norm, nz / norm
    geo[row, 0], geo[row, 1], geo[row, 2] = gx / geo_norm, gy / geo_norm, gz / geo_norm


@njit(cache=True, nogil=True)
def grown(array, capacity, count):
    """A copy of ``array`` with room for ``capacity`` rows, its first ``count`` rows kept."""
    out = np.empty((capacity,) + array.shape[1:], dtype=array.dtype)
    out[:count] = array[:count]
    return out


@njit(cache=True, nogil=True)
def pair_rays(need, frames, elements, origins, normals, sun, obs):
    """(r, 6) float32 rays: from each of an element's k points toward the Sun for the pairs
    needing it (``need & 1``; toward the part of the disk above the element's plane,
    :func:`raycast.renderer.rays.risen_sun`), then toward the observer (``need & 2``);
    origins (e, k, 3), element normals (e, 3)."""
    k = origins.shape[1]
    n_sun, n_obs = 0, 0
    for i in range(len(need)):
        n_sun += need[i] & 1
        n_obs += (need[i] >> 1) & 1
    rays = np.empty(((n_sun + n_obs) * k, 6), dtype=np.float32)
    row = 0
    for flag in (1, 2):
        for i in range(len(need)):
            if need[i] & flag:
                e, f = elements[i], frames[i]
                if flag == 1:
                    dx, dy, dz = risen_sun(normals[e, 0], normals[e, 1], normals[e, 2], sun[f, 0], sun[f, 1], sun[f, 2])
                else:
                    dx, dy, dz = obs[f, 0], obs[f, 1], obs[f, 2]
                for j in range(k):
                    for x in range(3):
                        rays[row, x] = origins[e, j, x]
                    rays[row, 3], rays[row, 4], rays[row, 5] = dx, dy, dz
                    row += 1
    return rays


@njit(cache=True, nogil=True)
def nearest_lobes(class_normal, class_lobed, sun, obs):
    """(m,) float64: each frame's smallest angle between its half vector and the nominal
    normal of a class of a pure-lobe material (``class_lobed``) facing both the Sun and the
    observer; pi where there is none (or no half vector)."""
    m = len(sun)
    angle = np.full(m, math.pi)
    for f in range(m):
        sx, sy, sz = sun[f, 0], sun[f, 1], sun[f, 2]
        ox, oy, oz = obs[f, 0], obs[f, 1], obs[f, 2]
        hx, hy, hz = sx + ox, sy + oy, sz + oz
        h_norm = math.sqrt(hx * hx + hy * hy + hz * hz)
        if h_norm <= 1e-6:
            continue
        hx, hy, hz = hx / h_norm, hy / h_norm, hz / h_norm
        best = -1.0
        for c in range(len(class_normal)):
            nx, ny, nz = class_normal[c, 0], class_normal[c, 1], class_normal[c, 2]
            cos_h = nx * hx + ny * hy + nz * hz
            # The facing tests only for a class nearer than the nearest so far.
            if cos_h <= best or not class_lobed[c]:
                continue
            if nx * sx + ny * sy + nz * sz > 0.0 and nx * ox + ny * oy + nz * oz > 0.0:
                best = cos_h
        if best > -1.0:
            angle[f] = math.acos(min(best, 1.0))
    return angle


@njit(cache=True, nogil=True)
def far_pairs(
    need,
    frames,
    elements,
    words,
    sun_nodes,
    sun_weights,
    obs_nodes,
    obs_weights,
    element_normal,
    far,
    sun,
    obs,
    nearest,
):
    """The pairs no exact ray needs to decide: their element's normals are all further from the
    frame's half vector than ``far[:, 0]`` (e, 3: the angle, its cosine and its sine) beyond the
    frame's ``nearest`` lobe (:func:`nearest_lobes`; an angle < 0: never). Such a pair is
    counted by the bilinear interpolation of its bits toward the Sun times toward the observer
    instead.

    Returns
    -------
    need : (p,) uint8, the pairs' ``need`` with the skipped ones' cleared (no ray is cast).
    blend : (p,) float32, the skipped pairs' interpolated visibility, -1 for the others.
    """
    p, m = len(need), len(sun)
    kept = need.copy()
    blend = np.full(p, -1.0, dtype=np.float32)
    one = np.uint64(1)
    half = np.zeros((m, 3))
    near_cos, near_sin = np.empty(m), np.empty(m)
    for f in range(m):
        hx, hy, hz = sun[f, 0] + obs[f, 0], sun[f, 1] + obs[f, 1], sun[f, 2] + obs[f, 2]
        h_norm = math.sqrt(hx * hx + hy * hy + hz * hz)
        if h_norm > 1e-6:
            half[f, 0], half[f, 1], half[f, 2] = hx / h_norm, hy / h_norm, hz / h_norm
        near_cos[f], near_sin[f] = math.cos(nearest[f]), math.sin(nearest[f])
    for i in range(p):
        e, f = elements[i], frames[i]
        if far[e, 0] < 0.0 or far[e, 0] + nearest[f] >= math.pi:
            continue
        cos_h = (
            element_normal[e, 0] * half[f, 0] + element_normal[e, 1] * half[f, 1] + element_normal[e, 2] * half[f, 2]
        )
        # cos(far + nearest), the largest cosine a pair without a ray may have.
        if cos_h >= far[e, 1] * near_cos[f] - far[e, 2] * near_sin[f]:
            continue
        w, shift = e >> 6, np.uint64(e & 63)
        toward_sun, toward_obs = 0.0, 0.0
        for j in range(4):
            toward_sun += sun_weights[f, j] * ((words[sun_nodes[f, j], w] >> shift) & one)
            toward_obs += obs_weights[f, j] * ((words[obs_nodes[f, j], w] >> shift) & one)
        blend[i] = toward_sun * toward_obs
        kept[i] = 0
    return kept, blend


@njit(cache=True, nogil=True)
def open_fraction(need, occluded, k, blend):
    """(p,) float32: the fraction of each pair's k points with both rays open, from the
    ``occluded`` flags of :func:`pair_rays`' rays (pairs without a ray are open that way), or
    the pair's ``blend`` where it is not negative (:func:`far_pairs`)."""
    n = len(need)
    sun_row = 0
    obs_row = 0
    for i in range(n):
        obs_row += k * (need[i] & 1)  # the observer's rays follow all the Sun's
    fraction = np.empty(n, dtype=np.float32)
    for i in range(n):
        toward_sun, toward_obs = need[i] & 1, (need[i] >> 1) & 1
        count = 0
        for j in range(k):
            if not ((toward_sun and occluded[sun_row + j]) or (toward_obs and occluded[obs_row + j])):
                count += 1
        sun_row += k * toward_sun
        obs_row += k * toward_obs
        fraction[i] = blend[i] if blend[i] >= 0.0 else count / k
    return fraction


@njit(cache=True, nogil=True)
def visibility_rays(points, normals, directions, band, offset):
    """Rays from elements toward grid directions, for the visibility tables of the build.

    Every direction less than ``band`` (a sine) below an element's plane gets a ray; those
    below the plane take their mirror image above it (see ``raycast.renderer.cache._visibility``).

    Parameters
    ----------
    points, normals : (e, 3) float, element centroids and unit geometric normals.
    directions : (d, 3) float, unit grid directions.
    band : float; offset : float, how far above its element a ray starts.

    Returns
    -------
    rays : (r, 6) float32; element, direction : (r,) int32, each ray's pair.
    """
    n_elements, n_directions = len(points), len(directions)
    count = 0
    for e in range(n_elements):
        for d in range(n_directions):
            h = normals[e, 0] * directions[d, 0] + normals[e, 1] * directions[d, 1] + normals[e, 2] * directions[d, 2]
            if h > -band:
                count += 1
    rays = np.empty((count, 6), dtype=np.float32)
    element = np.empty(count, dtype=np.int32)
    direction = np.empty(count, dtype=np.int32)
    row = 0
    for e in range(n_elements):
        ox = points[e, 0] + offset * normals[e, 0]
        oy = points[e, 1] + offset * normals[e, 1]
        oz = points[e, 2] + offset * normals[e, 2]
        for d in range(n_directions):
            h = normals[e, 0] * directions[d, 0] + normals[e, 1] * directions[d, 1] + normals[e, 2] * directions[d, 2]
            if h <= -band:
                continue
            lift = -2.0 * min(h, 0.0)
            x = directions[d, 0] + lift * normals[e, 0]
            y = directions[d, 1] + lift * normals[e, 1]
            z = directions[d, 2] + lift * normals[e, 2]
            norm = np.sqrt(x * x + y * y + z * z)
            rays[row, 0], rays[row, 1], rays[row, 2] = ox, oy, oz
            rays[row, 3], rays[row, 4], rays[row, 5] = x / norm, y / norm, z / norm
            element[row], direction[row] = e, d
            row += 1
    return rays, element, direction


@njit(cache=True, nogil=True)
def clear_bits(bits, element, direction, occluded):
    """Clear the bit of each occluded ray's (element, direction) in ``bits`` (e, ceil(d / 8))
    uint8, element-major, bit order as ``numpy.packbits`` (direction d at bit 7 - d % 8 of byte d // 8)."""
    for r in range(len(occluded)):
        if occluded[r]:
            d = direction[r]
            bits[element[r], d >> 3] &= np.uint8(255 - (1 << (7 - (d & 7))))


@njit(cache=True, nogil=True, inline="always")
def _cube_cell(x, y, z, n):
    """The first of the four cube-map nodes around direction (x, y, z) (grid size n), as
    ``raycast.renderer.cache.cube_grid_weights`` numbers them; the others are +(n+1), +1, +(n+2)."""
    ax, ay, az = abs(x), abs(y), abs(z)
    if ax >= ay and ax >= az:
        axis, major, a, b = 0, x, y, z
    elif ay >= az:
        axis, major, a, b = 1, y, z, x
    else:
        axis, major, a, b = 2, z, x, y
    face = 2 * axis + (1 if major < 0.0 else 0)
    scale = n / (0.5 * math.pi)
    ia = min(max(int(math.floor((math.atan(a / abs(major)) + 0.25 * math.pi) * scale)), 0), n - 1)
    ib = min(max(int(math.floor((math.atan(b / abs(major)) + 0.25 * math.pi) * scale)), 0), n - 1)
    return face * (n + 1) * (n + 1) + ia * (n + 1) + ib


@njit(cache=True, nogil=True, inline="always")
def _all_blocked(words, first, n, w, bit):
    """Whether an element's bits (word w, mask bit) are clear at the four nodes of a cell."""
    return not (
        words[first, w] & bit
        or words[first + n + 1, w] & bit
        or words[first + 1, w] & bit
        or words[first + n + 2, w] & bit
    )


@njit(cache=True, nogil=True)
def slit_candidates(words, origins, normals, middles, grid_size, elements, segments):
    """The (element, slit segment) pairs whose segment's middle (``middles`` (s, 3)) lies above
    the element's plane in a direction whose cell has its four nodes blocked in the element's
    bits: those whose ray through the middle escapes may see out through the slit. Written to
    ``elements`` and ``segments``, element-major; returns how many there were (more than the
    arrays' size: call again with room for all)."""
    n = grid_size
    capacity = len(elements)
    count = 0
    one = np.uint64(1)
    for e in range(len(origins)):
        w = e >> 6
        bit = one << np.uint64(e & 63)
        for s in range(len(middles)):
            x, y, z = middles[s, 0] - origins[e, 0], middles[s, 1] - origins[e, 1], middles[s, 2] - origins[e, 2]
            if x * normals[e, 0] + y * normals[e, 1] + z * normals[e, 2] <= 0.0:
                continue
            if _all_blocked(words, _cube_cell(x, y, z, n), n, w, bit):
                if count < capacity:
                    elements[count], segments[count] = e, s
                count += 1
    return count


@njit(cache=True, nogil=True)
def slit_gap_nodes(
    words, origins, normals, segments, grid_size, step_rad, pair_elements, pair_segments, nodes, elements
):
    """The gap pairs (node, element) of the (element, segment) pairs that see out through a slit.

    Each of the segment's lines (``segments`` (s, 3, 2, 3): near side, middle, far side of the
    gap) is followed in directions at most ``step_rad`` apart as the element (``origins``,
    unit ``normals`` (e, 3)) sees them; where a direction above the element's plane lies in a
    cell whose four nodes are blocked in the element's bits (``words`` (d, w) uint64), the four
    are gap nodes. Pairs come element-major; each (node, element) is written once, to
    ``nodes`` and ``elements``; returns how many there were (more than the arrays' size: call
    again with room for all).
    """
    n = grid_size
    capacity = len(nodes)
    count = 0
    one = np.uint64(1)
    marked = np.zeros(words.shape[0], dtype=np.bool_)
    touched = np.empty(words.shape[0], dtype=np.int64)
    n_touched = 0
    current = -1
    for p in range(len(pair_elements)):
        e, s = pair_elements[p], pair_segments[p]
        if e != current:
            for t in range(n_touched):
                marked[touched[t]] = False
            n_touched = 0
            current = e
        w = e >> 6
        bit = one << np.uint64(e & 63)
        ox, oy, oz = origins[e, 0], origins[e, 1], origins[e, 2]
        nx, ny, nz = normals[e, 0], normals[e, 1], normals[e, 2]
        for line in range(segments.shape[1]):
            ax, ay, az = segments[s, line, 0, 0] - ox, segments[s, line, 0, 1] - oy, segments[s, line, 0, 2] - oz
            bx, by, bz = segments[s, line, 1, 0] - ox, segments[s, line, 1, 1] - oy, segments[s, line, 1, 2] - oz
            la = math.sqrt(ax * ax + ay * ay + az * az)
            lb = math.sqrt(bx * bx + by * by + bz * bz)
            if la == 0.0 or lb == 0.0:
                continue
            cosine = (ax * bx + ay * by + az * bz) / (la * lb)
            steps = max(1, int(math.ceil(math.acos(min(max(cosine, -1.0), 1.0)) / step_rad)))
            last = -1
            for j in range(steps + 1):
                t = j / steps
                x, y, z = ax + t * (bx - ax), ay + t * (by - ay), az + t * (bz - az)
                if x * nx + y * ny + z * nz <= 0.0:
                    continue
                first = _cube_cell(x, y, z, n)
                if first == last:
                    continue
                last = first
                if not _all_blocked(words, first, n, w, bit):
                    continue
                for node in (first, first + n + 1, first + 1, first + n + 2):
                    if not marked[node]:
                        marked[node] = True
                        touched[n_touched] = node
                        n_touched += 1
                        if count < capacity:
                            nodes[count], elements[count] = node, e
                        count += 1
    return count
