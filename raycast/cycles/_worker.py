"""The Blender side of `raycast.cycles`: build a Cycles scene once, render it frame by frame.

This module imports ``bpy`` and is only ever imported by `raycast.cycles` when it runs Cycles in
the calling process, or run as ``python -m raycast.cycles._worker JOB.npz OUT.npz`` when it runs
Cycles in a child process (the default: Blender bundles its own Embree, TBB and OpenImageIO, and a
crash or a symbol clash there must not take down a caller that also imports Open3D).

A job is a dict of arrays (see `render_job`); `raycast.cycles` validates every value before it
builds one, so nothing here re-checks user input.

Conventions, each verified by tests/test_cycles.py against closed forms:

- The Sun lamp's strength is its irradiance in W/m^2 on a surface facing it; we use
  ``SUN_IRRADIANCE_W_M2`` and divide by it.
- A pixel of the float (OpenEXR, 32-bit) render holds the mean radiance over the pixel in
  W/(m^2 sr), scene-linear: the Standard view transform, no look, exposure 0 and gamma 1 are set
  anyway, and Cycles' film exposure is 1.
- With the box pixel filter of width 1 px, every camera sample lands uniformly inside its own
  pixel, so sum(pixel) * pixel_area is an unbiased estimate of the radiance integrated over the
  projected footprint; dividing by the irradiance gives I/E in m^2/sr.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
import sys
import tempfile
import time

import bpy
from mathutils import Matrix
import numpy as np

__all__ = ["render_job", "SUN_IRRADIANCE_W_M2"]

SUN_IRRADIANCE_W_M2 = 1.0

# Gap between the camera and the nearest vertex; ortho cameras see from the clip plane onward.
_CAMERA_STANDOFF_FRACTION = 0.1
# Sample 0 sits at the pixel centre for every seed (measured: renders of 1 sample/px with
# different seeds agree to 1e-5), so it is skipped.
_SKIPPED_SAMPLES = 1
# Corner normals closer than this to their face's geometric normal mean a flat-shaded face.
_FLAT_NORMAL_TOLERANCE = 1e-5

_NODE_TYPES = {
    "Diffuse BSDF": "ShaderNodeBsdfDiffuse",
    "Glossy BSDF": "ShaderNodeBsdfGlossy",
    "Principled BSDF": "ShaderNodeBsdfPrincipled",
}


def render_job(job, on_frame=None):
    """Render every frame of a job with Cycles and return I/E per pass and frame.

    Parameters
    ----------
    job : dict
        ``vertices_m (V, 3)``, ``triangles (T, 3)``, ``material_index (T,)``,
        ``corner_normals (T, 3, 3)`` (optional; absent means flat shading),
        ``materials_json`` (str, a JSON list of material entries) -- or instead of the arrays
        ``obj_path`` (str, an OBJ file read by Blender's own importer) with
        ``material_names_json`` (str, a JSON list naming each entry's material) --, ``sun_body (m, 3)``,
        ``obs_body (m, 3)`` (unit vectors in the mesh frame), ``passes (p, 2)`` (samples, seed
        of each render of every frame), ``resolution_px`` (pixels across the larger side of the
        projected footprint), ``sun_angle_deg``, ``threads`` (0 = all cores) and the object's
        shadow terminator offsets ``terminator_geometry_offset`` and ``terminator_shading_offset``.
    on_frame : callable or None
        Called with the frame index after each frame's passes are done.

    Returns
    -------
    dict
        ``intensity_rgb_m2_sr (p, m, 3)``, ``frame_seconds (p, m)`` (wall time of render plus
        read-back), ``frame_cpu_seconds (p, m)`` (CPU time of all threads for the same),
        ``resolution_px (m, 2)`` (x, y), ``pixel_size_m (m,)`` and ``setup_seconds`` (scene
        construction).
    """
    start = time.perf_counter()
    scene = _new_scene(job)
    vertices = _import_obj(scene, job) if "obj_path" in job else _add_mesh(scene, job)
    sun = _add_sun(scene, float(job["sun_angle_deg"]))
    camera = _add_camera(scene)

    sun_body = np.asarray(job["sun_body"], dtype=float)
    obs_body = np.asarray(job["obs_body"], dtype=float)
    passes = np.asarray(job["passes"], dtype=int)
    n_frames, n_passes = len(sun_body), len(passes)
    framing = _framing(vertices, obs_body, int(job["resolution_px"]))

    intensity = np.zeros((n_passes, n_frames, 3))
    frame_seconds = np.zeros((n_passes, n_frames))
    frame_cpu_seconds = np.zeros((n_passes, n_frames))
    with tempfile.TemporaryDirectory(prefix="rsodb-cycles-", dir=_scratch_dir()) as scratch:
        exr_path = str(Path(scratch) / "frame.exr")
        scene.render.filepath = exr_path
        _warm_up(scene, sun, camera, sun_body[0], framing)
        setup_seconds = time.perf_counter() - start
        for frame in range(n_frames):
            sun.matrix_world = Matrix(_frame_pointing(sun_body[frame]).tolist())
            camera.matrix_world = Matrix(framing["camera_matrix"][frame].tolist())
            camera.data.ortho_scale = float(framing["ortho_scale_m"][frame])
            camera.data.clip_start = float(framing["clip_start_m"][frame])
            camera.data.clip_end = float(framing["clip_end_m"][frame])
            scene.render.resolution_x = int(framing["resolution_px"][frame, 0])
            scene.render.resolution_y = int(framing["resolution_px"][frame, 1])
            pixel_area_m2 = float(framing["pixel_size_m"][frame]) ** 2
            for index, (samples, seed) in enumerate(passes):
                tick, cpu_tick = time.perf_counter(), time.process_time()
                # Cycles puts sample 0 of every pixel at the pixel centre, whatever the seed;
                # that biases the area of edge pixels by O(1/samples). Render samples 1..N.
                scene.cycles.samples = int(samples) + _SKIPPED_SAMPLES
                scene.cycles.sample_subset_length = int(samples)
                scene.cycles.seed = int(seed)
                bpy.ops.render.render(write_still=True, scene=scene.name)
                radiance_sum = _pixel_sum(exr_path)
                intensity[index, frame] = radiance_sum * pixel_area_m2 / SUN_IRRADIANCE_W_M2
                frame_seconds[index, frame] = time.perf_counter() - tick
                frame_cpu_seconds[index, frame] = time.process_time() - cpu_tick
            if on_frame is not None:
                on_frame(frame)
    return {
        "intensity_rgb_m2_sr": intensity,
        "frame_seconds": frame_seconds,
        "frame_cpu_seconds": frame_cpu_seconds,
        "resolution_px": framing["resolution_px"],
        "pixel_size_m": framing["pixel_size_m"],
        "setup_seconds": np.float64(setup_seconds),
    }


def _warm_up(scene, sun, camera, sun_direction, framing):
    """One tiny render, so that loading Cycles' kernels counts as setup, not as frame 0."""
    sun.matrix_world = Matrix(_frame_pointing(sun_direction).tolist())
    camera.matrix_world = Matrix(framing["camera_matrix"][0].tolist())
    camera.data.ortho_scale = float(framing["ortho_scale_m"][0])
    scene.render.resolution_x = scene.render.resolution_y = 8
    scene.cycles.samples = 1 + _SKIPPED_SAMPLES
    scene.cycles.sample_subset_length = 1
    bpy.ops.render.render(write_still=True, scene=scene.name)


def _scratch_dir():
    """A RAM-backed directory for the per-frame EXR when there is one."""
    return "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else None


def _new_scene(job):
    """An empty scene set up for direct-light-only, unbiased, float output rendering."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    cycles = scene.cycles
    cycles.device = "CPU"
    cycles.use_adaptive_sampling = False
    cycles.use_denoising = False
    cycles.use_animated_seed = False
    # Direct light only: camera ray, one shading point, shadow rays toward the Sun.
    cycles.max_bounces = 0
    cycles.diffuse_bounces = 0
    cycles.glossy_bounces = 0
    cycles.transmission_bounces = 0
    cycles.volume_bounces = 0
    cycles.transparent_max_bounces = 0
    cycles.caustics_reflective = False
    cycles.caustics_refractive = False
    # Defaults that would bias the comparison: glossy blur widens highlights, clamping and the
    # light threshold cut bright or faint samples.
    cycles.blur_glossy = 0.0
    cycles.sample_clamp_direct = 0.0
    cycles.sample_clamp_indirect = 0.0
    cycles.light_sampling_threshold = 0.0
    cycles.use_sample_subset = True
    cycles.sample_offset = _SKIPPED_SAMPLES
    cycles.pixel_filter_type = "BOX"
    cycles.filter_width = 1.0
    cycles.film_exposure = 1.0
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    scene.render.use_compositing = False
    scene.render.use_sequencer = False
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = 1.0
    scene.render.pixel_aspect_y = 1.0
    scene.render.use_persistent_data = True
    threads = int(job["threads"])
    scene.render.threads_mode = "FIXED" if threads > 0 else "AUTO"
    if threads > 0:
        scene.render.threads = threads
    image = scene.render.image_settings
    image.file_format = "OPEN_EXR"
    image.color_depth = "32"
    image.exr_codec = "NONE"
    image.color_mode = "RGB"

    world = bpy.data.worlds.new("black")
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    background.inputs["Strength"].default_value = 0.0
    scene.world = world
    return scene


def _add_mesh(scene, job):
    """The triangles, their materials and, when given, their per-corner shading normals;
    returns the vertices."""
    vertices = np.asarray(job["vertices_m"], dtype=float)
    triangles = np.asarray(job["triangles"], dtype=int)
    mesh = bpy.data.meshes.new("model")
    mesh.from_pydata(vertices.tolist(), [], triangles.tolist())
    for entry in json.loads(str(job["materials_json"])):
        mesh.materials.append(_material(entry))
    mesh.polygons.foreach_set("material_index", np.asarray(job["material_index"], dtype=np.int32))
    if "corner_normals" in job:
        corner_normals = np.asarray(job["corner_normals"], dtype=float)
        smooth = _smooth_faces(vertices, triangles, corner_normals)
        mesh.polygons.foreach_set("use_smooth", smooth)
        mesh.normals_split_custom_set(corner_normals.reshape(-1, 3).tolist())
    mesh.update()
    model = bpy.data.objects.new("model", mesh)
    _set_terminator_offsets(model, job)
    scene.collection.objects.link(model)
    return vertices


def _set_terminator_offsets(model, job):
    """The object's shadow terminator offsets, from the job."""
    # The shadow terminator offsets live on the object (Blender 5: Object.shadow_terminator_*;
    # the like-named properties under object.cycles are leftovers that Cycles no longer reads).
    # Blender's default geometry offset (0.1) starts shadow rays off low-poly smooth-shaded faces
    # as if from the smooth surface: it lights tube segments that the mesh's own steps shadow at
    # grazing Sun. The job's default (0) renders the mesh as it is.
    model.shadow_terminator_geometry_offset = float(job["terminator_geometry_offset"])
    model.shadow_terminator_shading_offset = float(job["terminator_shading_offset"])


def _import_obj(scene, job):
    """An OBJ file as Blender's own importer reads it (its triangulation, its normals), with
    the job's materials put in the slots of the same names; returns the world-space vertices."""
    before = set(bpy.data.objects)
    bpy.ops.wm.obj_import(filepath=str(job["obj_path"]), forward_axis="Y", up_axis="Z")
    entries = dict(zip(json.loads(str(job["material_names_json"])), json.loads(str(job["materials_json"]))))
    built, vertices = {}, []
    for model in (ob for ob in bpy.data.objects if ob not in before and ob.type == "MESH"):
        if model.name not in scene.collection.all_objects:
            scene.collection.objects.link(model)
        _set_terminator_offsets(model, job)
        for slot in model.material_slots:
            name = slot.material.name if slot.material is not None else ""
            if name not in entries:
                raise KeyError(f"the OBJ's material {name!r} has no entry in the job")
            slot.material = built.setdefault(name, _material(entries[name]))
        local = np.empty(3 * len(model.data.vertices))
        model.data.vertices.foreach_get("co", local)
        matrix = np.array(model.matrix_world)
        vertices.append(local.reshape(-1, 3) @ matrix[:3, :3].T + matrix[:3, 3])
    return np.concatenate(vertices)


def _smooth_faces(vertices, triangles, corner_normals):
    """(T,) bool: faces whose corner normals differ from their geometric normal."""
    corners = vertices[triangles]
    face_normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(face_normal, axis=1, keepdims=True)
    face_normal = np.divide(face_normal, length, out=np.zeros_like(face_normal), where=length > 0)
    deviation = np.abs(corner_normals - face_normal[:, None, :]).max(axis=(1, 2))
    return deviation > _FLAT_NORMAL_TOLERANCE


def _material(entry):
    """A Blender material holding the shader node(s) of a materials-JSON entry."""
    material = bpy.data.materials.new(entry["blender_node"])
    tree = material.node_tree
    for node in list(tree.nodes):
        if node.type != "OUTPUT_MATERIAL":
            tree.nodes.remove(node)
    output = next(node for node in tree.nodes if node.type == "OUTPUT_MATERIAL")
    tree.links.new(_shader_node(tree, entry).outputs[0], output.inputs["Surface"])
    return material


def _shader_node(tree, entry):
    """The node of one entry: a BSDF, or a Mix Shader fed by the BSDFs of its two ``shaders``."""
    kind = entry["blender_node"]
    if kind == "Mix Shader":
        mix = tree.nodes.new("ShaderNodeMixShader")
        mix.inputs["Fac"].default_value = entry["fac"]
        for socket, shader in zip((1, 2), entry["shaders"]):
            tree.links.new(_shader_node(tree, shader).outputs[0], mix.inputs[socket])
        return mix
    bsdf = tree.nodes.new(_NODE_TYPES[kind])
    if kind == "Diffuse BSDF":
        bsdf.inputs["Color"].default_value = (*entry["color"], 1.0)
        bsdf.inputs["Roughness"].default_value = entry.get("roughness", 0.0)
    elif kind == "Glossy BSDF":
        bsdf.distribution = entry.get("distribution", "GGX")
        bsdf.inputs["Color"].default_value = (*entry["color"], 1.0)
        bsdf.inputs["Roughness"].default_value = entry["roughness"]
    else:
        bsdf.distribution = entry.get("distribution", "GGX")
        bsdf.inputs["Base Color"].default_value = (*entry["base_color"], 1.0)
        bsdf.inputs["Metallic"].default_value = entry["metallic"]
        bsdf.inputs["Roughness"].default_value = entry["roughness"]
        bsdf.inputs["Specular IOR Level"].default_value = entry["specular_ior_level"]
        bsdf.inputs["IOR"].default_value = entry.get("ior", 1.5)
    return bsdf


def _add_sun(scene, sun_angle_deg):
    light = bpy.data.lights.new("sun", "SUN")
    light.energy = SUN_IRRADIANCE_W_M2
    light.angle = math.radians(sun_angle_deg)
    light.use_shadow = True
    sun = bpy.data.objects.new("sun", light)
    scene.collection.objects.link(sun)
    return sun


def _add_camera(scene):
    data = bpy.data.cameras.new("observer")
    data.type = "ORTHO"
    data.sensor_fit = "AUTO"
    data.shift_x = 0.0
    data.shift_y = 0.0
    camera = bpy.data.objects.new("observer", data)
    scene.collection.objects.link(camera)
    scene.camera = camera
    return camera


def _frame_pointing(direction):
    """(4, 4) world matrix of an object whose local +Z axis is `direction` (a unit vector).

    Blender's lamps shine and cameras look along their local -Z, so a Sun lamp with +Z toward
    the Sun lights the mesh along -sun_body, and a camera with +Z toward the observer looks
    along -obs_body.
    """
    return _pointing_matrices(np.asarray(direction, dtype=float)[None, :])[0]


def _pointing_matrices(directions):
    """(m, 4, 4) rotations whose third column is `directions` (m, 3); up is body +Z when possible."""
    z_axis = directions
    up = np.where(np.abs(z_axis[:, 2:3]) < 0.9, [0.0, 0.0, 1.0], [0.0, 1.0, 0.0])
    x_axis = np.cross(up, z_axis)
    x_axis /= np.linalg.norm(x_axis, axis=1, keepdims=True)
    y_axis = np.cross(z_axis, x_axis)
    matrices = np.zeros((len(directions), 4, 4))
    matrices[:, :3, 0] = x_axis
    matrices[:, :3, 1] = y_axis
    matrices[:, :3, 2] = z_axis
    matrices[:, 3, 3] = 1.0
    return matrices


def _framing(vertices, obs_body, resolution_px):
    """Per-frame orthographic camera covering the projected footprint with square pixels.

    The pixel size is the footprint's larger side over `resolution_px`; one empty pixel is kept
    on every side so no sample of the object falls outside the film.

    Returns
    -------
    dict
        ``camera_matrix (m, 4, 4)``, ``ortho_scale_m (m,)``, ``resolution_px (m, 2)`` (x, y),
        ``pixel_size_m (m,)``, ``clip_start_m (m,)`` and ``clip_end_m (m,)``.
    """
    matrices = _pointing_matrices(obs_body)
    # (m, V, 3): vertex coordinates along the camera's x, y and viewing (+z, toward observer) axes
    local = np.einsum("vj,mjk->mvk", vertices, matrices[:, :3, :3])
    low, high = local.min(axis=1), local.max(axis=1)
    extent = high - low
    footprint_m = np.maximum(extent[:, :2].max(axis=1), 1e-6)
    pixel_size_m = footprint_m / resolution_px
    resolution = np.ceil(extent[:, :2] / pixel_size_m[:, None] - 1e-9).astype(int) + 2
    resolution = np.maximum(resolution, 3)
    ortho_scale_m = resolution.max(axis=1) * pixel_size_m

    standoff_m = _CAMERA_STANDOFF_FRACTION * np.maximum(extent.max(axis=1), 1e-3)
    centre_local = np.stack(
        [(low[:, 0] + high[:, 0]) / 2, (low[:, 1] + high[:, 1]) / 2, high[:, 2] + standoff_m], axis=1
    )
    matrices[:, :3, 3] = np.einsum("mjk,mk->mj", matrices[:, :3, :3], centre_local)
    return {
        "camera_matrix": matrices,
        "ortho_scale_m": ortho_scale_m,
        "resolution_px": resolution,
        "pixel_size_m": pixel_size_m,
        "clip_start_m": standoff_m / 2,
        "clip_end_m": extent[:, 2] + 2 * standoff_m,
    }


def _pixel_sum(exr_path):
    """(3,) sum over pixels of the rendered RGB radiance, W/(m^2 sr)."""
    image = bpy.data.images.load(exr_path)
    try:
        pixels = np.empty(len(image.pixels), dtype=np.float32)
        image.pixels.foreach_get(pixels)
        channels = image.channels
    finally:
        bpy.data.images.remove(image)
    return pixels.reshape(-1, channels)[:, :3].astype(np.float64).sum(axis=0)


def main(argv=None):
    """Child-process entry: ``python -m raycast.cycles._worker JOB.npz OUT.npz``.

    Writes ``frame N`` lines to stdout as frames finish; Blender's own console output is sent to
    stderr so it cannot be mistaken for progress.
    """
    job_path, out_path = (sys.argv[1:] if argv is None else argv)[:2]
    progress = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)
    with np.load(job_path, allow_pickle=False) as stored:
        job = {key: stored[key] for key in stored.files}
    result = render_job(job, on_frame=lambda frame: print(f"frame {frame}", file=progress))
    np.savez(out_path, **result)
    progress.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
