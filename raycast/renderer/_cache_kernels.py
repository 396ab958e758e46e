"""Compiled (numba) loops of the fast path (raycast.renderer.cache), where numpy needed (elements, frames) arrays.

* Bit-held elements (``raycast.renderer.cache._add_bit_weight``): their visibility bits are held as
  (directions, words) uint64, element ``e`` at bit ``e % 64`` of word ``e // 64``. For each frame
  the four cube-map nodes around the Sun and the four around the observer are ANDed (visible at
  all of them) and ORed (at any) one word at a time; an element's area is added to its groups
  where all eight agree, and the pairs where they differ are returned for exact rays. Only the
  set bits are read.
* Shading classes (:func:`class_sums`): the groups' gated areas, shading and geometric normals
  summed into their classes in one pass.
"""

from numba import njit
import numpy as np

from raycast.renderer.rays import SUN_RADIUS_SINE, risen_sun, sun_fraction

# De Bruijn sequence for the index of a word's lowest set bit.
_DEBRUIJN = np.uint64(0x03F79D71B4CB0A89)
_DEBRUIJN_INDEX = np.array(
    [
        0,
        1,
        48,
        2,
        57,
        49,
        28,
        3,
        61,
        58,
        50,
        42,
        38,
        29,
        17,
        4,
        62,
        55,
        59,
        36,
        53,
        51,
        43,
        22,
        45,
        39,
        33,
        30,
        24,
        18,
        12,
        5,
        63,
        47,
        56,
        27,
        60,
        41,
        37,
        16,
        54,
        35,
        52,
        21,
        44,
        32,
        23,
        11,
        46,
        26,
        40,
        15,
        34,
        20,
        31,
        10,
        25,
        14,
        19,
        9,
        13,
        8,
        7,
        6,
    ],
    dtype=np.int64,
)


def pack_words(bits):
    """(d, e) bool -> (d, ceil(e / 64)) uint64, element e at bit e % 64 of word e // 64."""
    packed = np.packbits(bits, axis=1, bitorder="little")
    padded = np.zeros((packed.shape[0], -(-packed.shape[1] // 8) * 8), dtype=np.uint8)
    padded[:, : packed.shape[1]] = packed
    return np.ascontiguousarray(padded).view("<u8")


@njit(cache=True, nogil=True)
def _lowest_bit(word):
    return _DEBRUIJN_INDEX[((word & (~word + np.uint64(1))) * _DEBRUIJN) >> np.uint64(58)]


@njit(cache=True, nogil=True)
def _add_element(out, frame, element, value, ptr, group, area):
    for k in range(ptr[element], ptr[element + 1]):
        out[frame, group[k]] += value * area[k]


def agreed_weight(out, words, sun_nodes, obs_nodes, sun, obs, normals, ptr, group, area):
    """Add the area lit and seen at all eight nodes to ``out``; return the pairs to decide by rays.

    Parameters
    ----------
    out : (m, g) float32, each group's area per frame, added to.
    words : (d, w) uint64 visibility bits.
    sun_nodes, obs_nodes : (m, 4) int64, the cube-map nodes around each frame's directions.
    sun, obs : (m, 3) float32 exact directions; normals : (e, 3) float32 element normals.
    ptr, group, area : the elements' (group, area) pairs, CSC-style (element e owns
        ``ptr[e]:ptr[e + 1]``).

    Returns
    -------
    frames, elements : (p,) int64, pairs visible at some node of both but not at all eight,
        and facing both exact directions.
    need : (p,) uint8, bit 0: the Sun's four nodes differ (cast toward the Sun), bit 1: the
        observer's do.
    """
    # The pairs go to arrays sized from a first guess (a thirty-second of all pairs; 1% is
    # usual); when they overflow, the loop runs again with room for all.
    capacity, add = max(4096, len(sun_nodes) * len(normals) // 32), True
    while True:
        frames, elements = np.empty(capacity, dtype=np.int64), np.empty(capacity, dtype=np.int64)
        need = np.empty(capacity, dtype=np.uint8)
        count = _agreed_weight(
            out, words, sun_nodes, obs_nodes, sun, obs, normals, ptr, group, area, frames, elements, need, add
        )
        if count <= capacity:
            return frames[:count], elements[:count], need[:count]
        capacity, add = count, False  # the first run added the agreed area in full


@njit(cache=True, nogil=True)
def _agreed_weight(out, words, sun_nodes, obs_nodes, sun, obs, normals, ptr, group, area, frames, elements, need, add):
    # The pair arrays come in full size: growing them inside the loop made it three times slower.
    m, n_words = sun_nodes.shape[0], words.shape[1]
    capacity = len(frames)
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
            while add and both != zero:
                bit = _lowest_bit(both)
                both &= both - one
                _add_element(out, f, base + bit, np.float32(1.0), ptr, group, area)
            while mixed != zero:
                bit = _lowest_bit(mixed)
                mixed &= mixed - one
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
def add_pairs(out, frames, elements, values, ptr, group, area):
    """out[frame, group] += value * area for each pair's element pieces."""
    for i in range(len(frames)):
        if values[i] != 0.0:
            _add_element(out, frames[i], elements[i], values[i], ptr, group, area)


@njit(cache=True, nogil=True)
def class_sums(weight, normal_geo, normal_shade, group_class, sun, obs, n_classes):
    """Each shading class's lit, seen and projected area, and its groups' shading normals.

    Parameters
    ----------
    weight : (m, g) float32, each group's lit-and-seen area per frame (negative: zero).
    normal_geo, normal_shade : (g, 3) float32, the groups' geometric and mean shading normals.
    group_class : (g,) int, each group's shading class.
    sun, obs : (m, 3) float32.
    n_classes : int.

    Returns
    -------
    area : (m, c) float32, sum of weight x max(n_geo . obs, 0) x the part of the solar disk
        above the group's plane (:func:`raycast.renderer.rays.sun_fraction`) over the class's
        groups (the gates of the geometric normal).
    normal : (m, c, 3) float32, the same sum of each group's shading normal (not normalised).
    geo : (m, c, 3) float32, and of each group's geometric normal.
    """
    m, n_groups = weight.shape
    area = np.zeros((m, n_classes), dtype=np.float32)
    normal = np.zeros((m, n_classes, 3), dtype=np.float32)
    geo = np.zeros((m, n_classes, 3), dtype=np.float32)
    for f in range(m):
        sx, sy, sz = sun[f, 0], sun[f, 1], sun[f, 2]
        ox, oy, oz = obs[f, 0], obs[f, 1], obs[f, 2]
        for g in range(n_groups):
            w = weight[f, g]
            if w <= 0.0:
                continue
            gx, gy, gz = normal_geo[g, 0], normal_geo[g, 1], normal_geo[g, 2]
            cos_o = gx * ox + gy * oy + gz * oz
            cos_s = gx * sx + gy * sy + gz * sz
            if cos_o <= 0.0 or cos_s <= -SUN_RADIUS_SINE:
                continue
            w *= cos_o * sun_fraction(cos_s)
            c = group_class[g]
            area[f, c] += w
            normal[f, c, 0] += w * normal_shade[g, 0]
            normal[f, c, 1] += w * normal_shade[g, 1]
            normal[f, c, 2] += w * normal_shade[g, 2]
            geo[f, c, 0] += w * gx
            geo[f, c, 1] += w * gy
            geo[f, c, 2] += w * gz
    return area, normal, geo


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
def open_fraction(need, occluded, k):
    """(p,) float32: the fraction of each pair's k points with both rays open, from the
    ``occluded`` flags of :func:`pair_rays`' rays (pairs without a ray are open that way)."""
    n = len(need)
    is_open = np.ones((n, k), dtype=np.bool_)
    row = 0
    for flag in (1, 2):
        for i in range(n):
            if need[i] & flag:
                for j in range(k):
                    if occluded[row]:
                        is_open[i, j] = False
                    row += 1
    fraction = np.empty(n, dtype=np.float32)
    for i in range(n):
        fraction[i] = is_open[i].sum() / k
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
