"""MP4 video of a reconstruction, rendered offscreen by MuJoCo (kinematics only, no physics).

The humanoid of the subject (:func:`grip.sim.model.load_model`) is put in the reconstruction's
pose at each video frame (:func:`grip.core.reference.pose_vector` scattered into ``qpos`` by
:func:`grip.sim.model.write_pose_vector`, then ``mj_forward``) and rendered by
:class:`mujoco.Renderer` from a camera that follows the pelvis (smoothed over
:attr:`VideoConfig.track_smoothing_s`, at a fixed azimuth and elevation). With a ground truth, a
second, translucent green humanoid shows it in the same scene. Frames are encoded with imageio's
ffmpeg plugin (H.264, yuv420p) to a temporary file and moved into place atomically.

OpenGL: MuJoCo chooses its offscreen backend from the ``MUJOCO_GL`` environment variable *when
``mujoco`` is first imported*. Without a display, set ``MUJOCO_GL=egl`` (GPU or Mesa EGL
drivers) or ``MUJOCO_GL=osmesa`` (software) before Python starts; ``grip export`` sets
``egl`` when the variable is unset. Without a working backend, :func:`write_video` raises
:class:`RenderBackendError` saying so.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
from scipy.ndimage import uniform_filter1d

from grip.core.body import BodyModel, BodyParams
from grip.core.mjcf import MjcfConfig
from grip.core.reconstruction import Reconstruction
from grip.core.reference import pose_vector
from grip.export.common import (
    ExportError,
    body_model,
    check_ground_truth,
    check_rotations,
    write_file,
)
from grip.kinematics.features import GroundTruth
from grip.sim.model import HumanoidIndex, load_model, write_pose_vector

_GT_RGBA = np.array([0.2, 0.85, 0.3, 0.35], dtype=np.float32)


class RenderBackendError(RuntimeError):
    """No OpenGL context could be created for offscreen rendering."""


@dataclass(frozen=True)
class VideoConfig:
    """Video options.

    Attributes:
        fps: Video frame rate, Hz; the reconstruction is sampled at the nearest frames.
        width: Image width, pixels (even: H.264 with yuv420p needs even sizes).
        height: Image height, pixels (even).
        distance_m: Camera distance from the tracked point, m.
        azimuth_deg: Camera azimuth, deg (MuJoCo convention: 90 looks along world +y; the
            default -45 looks at a subject facing +y from its front left).
        elevation_deg: Camera elevation, deg (negative looks down).
        track_smoothing_s: Width of the moving average over the pelvis trajectory that the
            camera follows, s (0: follow the pelvis exactly).
        gt_alpha: Opacity of the ground-truth humanoid, in (0, 1].
        quality: imageio/ffmpeg quality, 0 (worst) to 10 (best).
        shadows: Render shadows. Off by default: with Mesa's software EGL they made a
            320 x 240 frame ~10x slower (245 ms vs 23 ms measured here).
        reflections: Render the floor's reflections (~2x slower in software).
    """

    fps: float = 30.0
    width: int = 640
    height: int = 480
    distance_m: float = 4.0
    azimuth_deg: float = -45.0
    elevation_deg: float = -15.0
    track_smoothing_s: float = 0.5
    gt_alpha: float = 0.35
    quality: float = 7.0
    shadows: bool = False
    reflections: bool = False

    def __post_init__(self) -> None:
        if not self.fps > 0:
            raise ValueError(f"VideoConfig.fps must be positive, got {self.fps}")
        for name in ("width", "height"):
            v = getattr(self, name)
            if not (isinstance(v, int) and 16 <= v <= 4096 and v % 2 == 0):
                raise ValueError(f"VideoConfig.{name} must be an even number of pixels in "
                                 f"16..4096, got {v!r}")  # fmt: skip
        if not self.distance_m > 0:
            raise ValueError(f"VideoConfig.distance_m must be positive, got {self.distance_m}")
        if not self.track_smoothing_s >= 0:
            raise ValueError(f"VideoConfig.track_smoothing_s must be >= 0, "
                             f"got {self.track_smoothing_s}")  # fmt: skip
        if not 0 < self.gt_alpha <= 1:
            raise ValueError(f"VideoConfig.gt_alpha must be in (0, 1], got {self.gt_alpha}")
        if not 0 <= self.quality <= 10:
            raise ValueError(f"VideoConfig.quality must be in [0, 10], got {self.quality}")


def video_frames(n_frames: int, fps: float, video_fps: float) -> np.ndarray:
    """Indices of the reconstruction frames shown at ``video_fps``: the nearest frame to each
    video time ``k / video_fps`` over the clip's duration."""
    duration = (n_frames - 1) / fps
    k = np.arange(int(np.floor(duration * video_fps + 1e-9)) + 1)
    return np.minimum(np.rint(k * fps / video_fps).astype(np.int64), n_frames - 1)


def camera_track(root_pos: np.ndarray, fps: float, smoothing_s: float) -> np.ndarray:
    """``(T, 3)`` point the camera looks at: the pelvis trajectory under a centred moving
    average of ``smoothing_s`` seconds (edges held), world, m."""
    width = round(smoothing_s * fps)
    if width <= 1:
        return np.array(root_pos, dtype=np.float64)
    return uniform_filter1d(np.asarray(root_pos, dtype=np.float64), size=width, axis=0,
                            mode="nearest")  # fmt: skip


def _gl_hint() -> str:
    current = os.environ.get("MUJOCO_GL", "")
    return (f"offscreen OpenGL rendering is not available (MUJOCO_GL={current!r}). Set "
            "MUJOCO_GL=egl (needs GPU or Mesa EGL drivers, e.g. libegl1 and libgl1-mesa-dri) "
            "or MUJOCO_GL=osmesa (needs libosmesa6) in the environment before Python starts "
            "(MuJoCo reads it when it is first imported), or leave out the mp4 format")  # fmt: skip


def open_renderer(model: mujoco.MjModel, width: int, height: int) -> mujoco.Renderer:
    """A :class:`mujoco.Renderer` for ``model`` at ``width x height`` (the model's offscreen
    buffer is enlarged when needed).

    Raises:
        RenderBackendError: No OpenGL context could be created; the message says how to fix it.
    """
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), width)
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), height)
    try:
        return mujoco.Renderer(model, height=height, width=width)
    except (mujoco.FatalError, ImportError, OSError, RuntimeError, AttributeError) as e:
        raise RenderBackendError(f"{_gl_hint()} [{type(e).__name__}: {e}]") from e


def _model_for(bm: BodyModel) -> tuple[mujoco.MjModel, mujoco.MjData, HumanoidIndex]:
    model = load_model(bm, MjcfConfig(insole_sensors=False, imu_sensors=False))
    return model, mujoco.MjData(model), HumanoidIndex.from_model(model)


def render_frames(
    recon: Reconstruction,
    body: BodyParams | BodyModel | None = None,
    *,
    gt: GroundTruth | None = None,
    cfg: VideoConfig | None = None,
) -> Iterator[np.ndarray]:
    """Render the reconstruction frame by frame.

    Args:
        recon: The reconstruction.
        body: Subject (``None``: ``BodyParams()``).
        gt: Ground truth over the same frames, drawn as a translucent green humanoid on its own
            body (``gt.body``), or ``None``.
        cfg: Video options (``None``: :class:`VideoConfig` defaults).

    Yields:
        ``(height, width, 3)`` uint8 RGB images at ``cfg.fps``.

    Raises:
        RenderBackendError: No OpenGL backend (raised before the first image).
        ExportError: ``gt`` does not match the reconstruction's frames.
    """
    cfg = cfg or VideoConfig()
    if gt is not None:
        check_ground_truth(recon, gt)
    model, data, index = _model_for(body_model(body))
    frames = video_frames(recon.n_frames, recon.fps, cfg.fps)
    poses = pose_vector(recon.local_rot[frames], recon.root_pos[frames])
    look = camera_track(recon.root_pos, recon.fps, cfg.track_smoothing_s)[frames]
    gt_parts = None
    if gt is not None:
        gm, gd, gi = _model_for(body_model(gt.body))
        gt_parts = (gm, gd, gi, pose_vector(gt.local_rot[frames], gt.root_pos[frames]))
    option = mujoco.MjvOption()
    option.sitegroup[:] = 0  # IMU and insole sites off
    option.geomgroup[1] = 0  # sole pads off
    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_FREE
    camera.distance = cfg.distance_m
    camera.azimuth = cfg.azimuth_deg
    camera.elevation = cfg.elevation_deg
    renderer = open_renderer(model, cfg.width, cfg.height)
    try:
        for k in range(len(frames)):
            write_pose_vector(poses[k], index, data.qpos)
            mujoco.mj_forward(model, data)
            camera.lookat[:] = look[k]
            renderer.update_scene(data, camera, option)
            renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = cfg.shadows
            renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = cfg.reflections
            if gt_parts is not None:
                gm, gd, gi, gposes = gt_parts
                write_pose_vector(gposes[k], gi, gd.qpos)
                mujoco.mj_forward(gm, gd)
                scene = renderer.scene
                first = scene.ngeom
                mujoco.mjv_addGeoms(gm, gd, option, mujoco.MjvPerturb(),
                                    mujoco.mjtCatBit.mjCAT_DYNAMIC, scene)  # fmt: skip
                for g in range(first, scene.ngeom):  # MjvGeom structs: no array view
                    scene.geoms[g].rgba[:] = [*_GT_RGBA[:3].tolist(), cfg.gt_alpha]
            yield renderer.render().copy()
    finally:
        renderer.close()


def write_video(
    recon: Reconstruction,
    path: str | os.PathLike,
    body: BodyParams | BodyModel | None = None,
    *,
    gt: GroundTruth | None = None,
    cfg: VideoConfig | None = None,
) -> int:
    """Render (:func:`render_frames`) and encode an MP4, atomically.

    Returns:
        The number of video frames written.

    Raises:
        RenderBackendError: No OpenGL backend; nothing is written.
        ExportError: The file cannot be encoded or written (the message names it), a
            rotation is no rotation, or ``gt`` does not match the reconstruction.
    """
    import imageio.v2 as imageio

    cfg = cfg or VideoConfig()
    path = Path(path)
    check_rotations(recon, path)
    images = render_frames(recon, body, gt=gt, cfg=cfg)
    try:
        first = next(images)  # raises RenderBackendError before any file is created
        n = 0
        with tempfile.TemporaryDirectory(prefix="grip_video_") as tmp:
            tmp_file = Path(tmp) / "video.mp4"
            try:
                writer = imageio.get_writer(tmp_file, fps=cfg.fps, codec="libx264",
                                            quality=cfg.quality, pixelformat="yuv420p",
                                            macro_block_size=2)  # fmt: skip
                try:
                    for img in _chain(first, images):
                        writer.append_data(img)
                        n += 1
                finally:
                    writer.close()
            except RenderBackendError:
                raise
            except (OSError, RuntimeError, ValueError) as e:
                raise ExportError(f"{path}: cannot render or encode the video ({e})") from e

            def copy(f) -> None:
                with open(tmp_file, "rb") as src:
                    shutil.copyfileobj(src, f)

            write_file(path, copy)
    finally:
        images.close()  # frees the GL context even when encoding failed
    return n


def _chain(first: np.ndarray, rest: Iterator[np.ndarray]) -> Iterator[np.ndarray]:
    yield first
    yield from rest
