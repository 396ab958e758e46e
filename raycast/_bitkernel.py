"""Compiled loops of the fast path's bit-held elements (see raycast.cache._bit_weight).

The elements' visibility bits are held as (directions, words) uint64, element ``e`` at bit
``e % 64`` of word ``e // 64``. For each frame the four cube-map nodes around the Sun and the
four around the observer are ANDed (visible at all of them) and ORed (at any) one word at a
time; an element's area is added to its groups where all eight agree, and the pairs where
they differ are returned for exact rays. numpy needs a (elements, frames) float array for the
same sum; this reads only the set bits.
"""

import numpy as np
from numba import njit

# De Bruijn sequence for the index of a word's lowest set bit.
_DEBRUIJN = np.uint64(0x03F79D71B4CB0A89)
_DEBRUIJN_INDEX = np.array([
    0, 1, 48, 2, 57, 49, 28, 3, 61, 58, 50, 42, 38, 29, 17, 4, 62, 55, 59, 36, 53, 51, 43, 22, 45, 39, 33, 30,
    24, 18, 12, 5, 63, 47, 56, 27, 60, 41, 37, 16, 54, 35, 52, 21, 44, 32, 23, 11, 46, 26, 40, 15, 34, 20, 31,
    10, 25, 14, 19, 9, 13, 8, 7, 6], dtype=np.int64)


def pack_words(bits):
    """(d, e) bool -> (d, ceil(e / 64)) uint64, element e at bit e % 64 of word e // 64."""
    packed = np.packbits(bits, axis=1, bitorder="little")
    padded = np.zeros((packed.shape[0], -(-packed.shape[1] // 8) * 8), dtype=np.uint8)
    padded[:, :packed.shape[1]] = packed
    return np.ascontiguousarray(padded).view("<u8")


@njit(cache=True, nogil=True)
def _lowest_bit(word):
    return _DEBRUIJN_INDEX[((word & (~word + np.uint64(1))) * _DEBRUIJN) >> np.uint64(58)]


@njit(cache=True, nogil=True)
def _add_element(out, frame, element, value, ptr, group, area):
    for k in range(ptr[element], ptr[element + 1]):
        out[frame, group[k]] += value * area[k]


def agreed_weight(words, sun_nodes, obs_nodes, sun, obs, normals, ptr, group, area, n_groups):
    """Area lit and seen at all eight nodes, and the pairs to decide by rays.

    Parameters
    ----------
    words : (d, w) uint64 visibility bits.
    sun_nodes, obs_nodes : (m, 4) int64, the cube-map nodes around each frame's directions.
    sun, obs : (m, 3) float32 exact directions; normals : (e, 3) float32 element normals.
    ptr, group, area : the elements' (group, area) pairs, CSC-style (element e owns
        ``ptr[e]:ptr[e + 1]``).
    n_groups : int.

    Returns
    -------
    out : (m, g) float32, area of the elements visible at all four nodes of both directions.
    frames, elements : (p,) int64, pairs visible at some node of both but not at all eight,
        and facing both exact directions.
    need : (p,) uint8, bit 0: the Sun's four nodes differ (cast toward the Sun), bit 1: the
        observer's do.
    """
    # The pairs go to arrays sized from a first guess (a thirty-second of all pairs; 1% is
    # usual); when they overflow, the loop runs again with room for all.
    capacity = max(4096, len(sun_nodes) * len(normals) // 32)
    while True:
        frames, elements = np.empty(capacity, dtype=np.int64), np.empty(capacity, dtype=np.int64)
        need = np.empty(capacity, dtype=np.uint8)
        out, count = _agreed_weight(words, sun_nodes, obs_nodes, sun, obs, normals, ptr, group, area, n_groups,
                                    frames, elements, need)
        if count <= capacity:
            return out, frames[:count], elements[:count], need[:count]
        capacity = count


@njit(cache=True, nogil=True)
def _agreed_weight(words, sun_nodes, obs_nodes, sun, obs, normals, ptr, group, area, n_groups, frames, elements,
                   need):
    # The pair arrays come in full size: growing them inside the loop made it three times slower.
    m, n_words = sun_nodes.shape[0], words.shape[1]
    capacity = len(frames)
    out = np.zeros((m, n_groups), dtype=np.float32)
    count = 0
    zero, one = np.uint64(0), np.uint64(1)
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
            both = sun_all & obs_all
            mixed = sun_any & obs_any & ~both
            base = 64 * w
            while both != zero:
                bit = _lowest_bit(both)
                both &= both - one
                _add_element(out, f, base + bit, np.float32(1.0), ptr, group, area)
            while mixed != zero:
                bit = _lowest_bit(mixed)
                mixed &= mixed - one
                e = base + bit
                nx, ny, nz = normals[e, 0], normals[e, 1], normals[e, 2]
                if nx * sx + ny * sy + nz * sz <= 0.0 or nx * ox + ny * oy + nz * oz <= 0.0:
                    continue
                if count < capacity:
                    shift = np.uint64(bit)
                    frames[count] = f
                    elements[count] = e
                    need[count] = (((sun_all >> shift) & one) ^ one) | ((((obs_all >> shift) & one) ^ one) << one)
                count += 1
    return out, count


@njit(cache=True, nogil=True)
def add_pairs(out, frames, elements, values, ptr, group, area):
    """out[frame, group] += value * area for each pair's element pieces."""
    for i in range(len(frames)):
        if values[i] != 0.0:
            _add_element(out, frames[i], elements[i], values[i], ptr, group, area)
