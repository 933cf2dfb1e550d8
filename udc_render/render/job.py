"""Render a scene to band images: radiance at the sensor in K wavelength bands (+ depth).

Three paths, chosen by what the scene needs and recorded in the metadata:

- ``analytic`` (auto for the monitor alone through a pinhole): the exact pixel-area means of the panel
  (render.analytic), no Monte Carlo and no Mitsuba; Mitsuba's rgb path converges to it (tests).
- ``rgb_matrix`` (the monitor alone in a dark room): light transport does not depend on wavelength,
  so one RGB render of the panel's drive levels w_c(x) (c = R, G, B) gives every band exactly:
  L_k(x) = Σ_c w_c(x) · P_ck, with P_ck the band-mean of primary c's radiance over band k.
- ``spectral`` (3D scenes, user XML, or forced): Mitsuba's spectral variant with a `specfilm` of box
  responses, ``bands_per_render`` bands per render (each render samples wavelengths only inside
  its bands).

Band values are pixel-area means of band-mean radiance, W·sr⁻¹·m⁻²·nm⁻¹ (box pixel filter; no
cos⁴ fall-off and no exposure: those belong to the sensor model). The grid covers the sensor plus a
margin of ``margin_px`` on every side; the sensor frame is ``bands[:, m:-m, m:-m]``.

Samples: ``spp`` split into equal passes with seeds from SeedSequence([seed, group, pass]), each pass
drawn by ``render.sampler`` (a Mitsuba sampler; its count rounded up as the sampler requires, and
recorded as rendered). Every pass is an independent randomisation (its own seed), so the spread between
passes measures the image's own Monte Carlo noise even for correlated samplers (relative RMS ‖σ‖₂/‖x‖₂
over all bands and pixels, x the noise-free image), recorded as ``noise_rel``. With a noise target, two
pilot passes at ``PILOT_SPP`` estimate the noise and spp = ⌈pilot·(σ/target)²⌉ (the 1/√N law of
independent samples: conservative for samplers that converge faster).
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import asdict
from pathlib import Path

import numpy as np
from tqdm import tqdm

from udc_render.content import spectra
from udc_render.content.monitor_image import DisplayImageError, panel_drive
from udc_render.render import mitsuba_scene as ms
from udc_render.render.analytic import monitor_area_means, monitor_depth_m
from udc_render.render.band_image import BandImage, band_names
from udc_render.render.errors import RenderError
from udc_render.render.variants import set_variant
from udc_render.render.xml_camera import load_xml, resolve_xml_camera
from udc_render.scene import MitsubaXML, Monitor, Scene
from udc_render.scene.geometry import CameraGeometry, axial_depth_m, camera_geometry

PILOT_SPP = 4
MAX_SPP = 1 << 14
# largest pass; progress ticks once per pass (a 3D pass is ~1 min at full size)
PASS_SPP = {"rgb_matrix": 64, "spectral": 8}


def analytic_applies(scene: Scene) -> bool:
    """The monitor alone seen through a pinhole: its render is an exact area integral (render.analytic)."""
    return isinstance(scene.content, Monitor) and scene.lens.model == "pinhole"


def choose_path(scene: Scene) -> str:
    """The render path: the scene's, or for 'auto' the exact 'analytic' one for the monitor alone through a
    pinhole, 'rgb_matrix' (one Mitsuba RGB render) for the monitor through a thin lens, else 'spectral'."""
    if scene.render.path != "auto":
        if scene.render.path == "analytic" and not analytic_applies(scene):
            raise RenderError(f"{scene.source}: render.path = \"analytic\": needs monitor content and lens.model = "
                              f"\"pinhole\" (the exact area integral); use \"auto\", \"rgb_matrix\" or \"spectral\"")
        return scene.render.path
    if analytic_applies(scene):
        return "analytic"
    return "rgb_matrix" if isinstance(scene.content, Monitor) else "spectral"


def pass_seed(seed: int, group: int, pass_index: int, pilot: bool = False) -> int:
    """Mitsuba's uint32 seed of one pass: SeedSequence([seed, group, pass(, 1 for pilots)]). numpy pads the
    entropy with zeros to 4 words, so pass 0 ends the key in a zero that is not there: (seed, g, 0, 0) is also
    [seed, g] and [seed] (g = 0), which no other pass or pilot is ((seed, g, p, 0) against (seed, g, p, 1)):
    every pass has its own seed (tests/udc_render/test_dataset_streams.py); the bytes of every render stay."""
    key = [seed, group, pass_index] + ([1] if pilot else [])
    return int(np.random.SeedSequence(key).generate_state(1)[0])


def pass_statistics(passes: np.ndarray, matrix: np.ndarray | None = None) -> tuple[np.ndarray, float, float]:
    """Mean of P independent passes [P, C, H, W] (float32), and over all band values the sums
    Σ σ² (variance of the mean) and Σ x̄², for the relative noise ‖σ‖₂/‖x‖₂ = sqrt(Σσ²/(Σx̄² − Σσ²)) (x the
    noise-free image; the norm of the study's relative error). With `matrix` [C, K] the bands are
    x_k = Σ_c M_ck w_c of the rendered channels w (the rgb path), and both sums follow exactly from the C × C
    covariance and Gram matrices summed over pixels."""
    p = passes.shape[0]
    mean = passes.mean(0, dtype=np.float64)
    flat = mean.reshape(mean.shape[0], -1)
    gram = flat @ flat.T
    if p > 1:
        dev = (passes - mean[None].astype(np.float32)).reshape(p, mean.shape[0], -1).astype(np.float64)
        cov = np.einsum("pcn,pdn->cd", dev, dev) / (p - 1) / p
    else:
        cov = np.full_like(gram, np.nan)
    if matrix is None:
        var_sum, sq_sum = float(np.trace(cov)), float(np.trace(gram))
    else:
        var_sum, sq_sum = float(np.trace(matrix.T @ cov @ matrix)), float(np.trace(matrix.T @ gram @ matrix))
    return mean.astype(np.float32), var_sum, sq_sum


class _Job:
    """One scene prepared for rendering: Mitsuba scene(s), films, and how bands are formed."""

    def __init__(self, scene: Scene, path: str):
        self.scene, self.path = scene, path
        self.edges = np.asarray(scene.bands.edges_nm)
        self.mi, self.backend = set_variant("rgb" if path == "rgb_matrix" else "spectral")
        mi = self.mi
        self.meta: dict = {}
        content = scene.content
        if isinstance(content, MitsubaXML):  # the pose is the scene's: resolve_xml_camera took the XML's
            self.xml_scene = load_xml(scene, mi)
            self.meta["xml_camera"] = (asdict(content.xml_camera) if content.xml_camera is not None else
                                       "not used (content.use_xml_camera = false): the scene file's [camera]")
        self.geom: CameraGeometry = camera_geometry(scene)
        self.matrix: np.ndarray | None = None  # [3, K] monitor primaries' band means (monitor content only)
        default_depth = 2 if isinstance(content, Monitor) else 8
        self.max_depth = scene.render.max_depth or default_depth
        self.integrator = {"type": "path", "max_depth": self.max_depth}
        if isinstance(content, Monitor):
            self.drive, self.primaries, self.matrix, meta = monitor_content(scene, self.geom)
            self.meta.update(meta)
            shape = ms.monitor_shape(mi, content.size_m, self.drive, None if path == "rgb_matrix" else self.primaries)
            self.content = {"type": "scene", "monitor": shape}
        elif isinstance(content, MitsubaXML):
            self.content = None
        elif scene.content_type == "room":
            self.content = ms.room(mi, content)
        else:
            self.content = ms.hdr_room(mi, content, self.geom.origin_m)
        groups = [(0, len(self.edges) - 1)] if path == "rgb_matrix" else [
            (a, min(a + scene.render.bands_per_render, len(self.edges) - 1))
            for a in range(0, len(self.edges) - 1, scene.render.bands_per_render)]
        self.groups = groups
        self._scenes = {}

    def _mitsuba_scene(self, g: int):
        if g in self._scenes:
            return self._scenes[g]
        mi, geom = self.mi, self.geom
        a, b = self.groups[g]
        film = ms.rgb_film(geom) if self.path == "rgb_matrix" else ms.band_film(geom, self.edges[a:b + 1])
        sens = ms.sensor(mi, geom, self.scene.lens, film, {"type": self.scene.render.sampler, "sample_count": 1})
        if self.content is None:
            built = (self.xml_scene, mi.load_dict(sens), mi.load_dict(self.integrator))
        else:
            built = (mi.load_dict({**self.content, "sensor": sens, "integrator": self.integrator}), None, None)
        self._scenes = {g: built}  # keep one group's scene alive at a time
        return built

    def sample_count(self, spp: int) -> int:
        """The samples per pixel the scene's sampler takes for a request of `spp` (Mitsuba rounds up:
        stratified to a square, ldsampler to a power of 4, orthogonal to a prime², multijitter to x·y)."""
        mi = self.mi
        level = mi.log_level()
        mi.set_log_level(mi.LogLevel.Error)
        try:
            return int(mi.load_dict({"type": self.scene.render.sampler, "sample_count": int(spp)}).sample_count())
        finally:
            mi.set_log_level(level)

    def render_group(self, g: int, spp: int, seed: int) -> np.ndarray:
        """Band values [k, H, W] of group g (rgb path: the drive-weighted RGB [3, H, W])."""
        sc, sens, integ = self._mitsuba_scene(g)
        img = self.mi.render(sc, sensor=sens, integrator=integ, spp=spp, seed=seed) if sens is not None else \
            self.mi.render(sc, spp=spp, seed=seed)
        img = np.array(img, dtype=np.float32).transpose(2, 0, 1)
        if self.path == "rgb_matrix":
            return img[:3]
        a, b = self.groups[g]
        return img[:b - a] / np.diff(self.edges[a:b + 1]).astype(np.float32)[:, None, None]

    def render_all(self, spp: int, n_pass: int, seed: int, pilot: bool = False, bar=None) -> tuple[list, float | None]:
        """Each group's mean over `n_pass` passes of `spp` (group by group: one Mitsuba scene
        alive at a time) and the relative noise of the bands (None for a single pass)."""
        means, var_sum, sq_sum = [], 0.0, 0.0
        matrix = self.matrix if self.path == "rgb_matrix" else None
        for g in range(len(self.groups)):
            passes = []
            for p in range(n_pass):
                passes.append(self.render_group(g, spp, pass_seed(seed, g, p, pilot)))
                if bar is not None:
                    bar.update()
            mean, v, q = pass_statistics(np.stack(passes), matrix)
            means.append(mean)
            var_sum, sq_sum = var_sum + v, sq_sum + q
        # E[x̄²] = x² + σ²: relative to the noise-free image, Σx² ≈ Σx̄² − Σσ²
        noise = math.sqrt(var_sum / (sq_sum - var_sum)) if n_pass > 1 and sq_sum > var_sum else (
            math.inf if n_pass > 1 and var_sum > 0 else None)
        return means, noise

    def depth(self) -> np.ndarray:
        """Axial distance (m) at every pixel centre; inf where the ray leaves the scene."""
        mi = self.mi
        sens = mi.load_dict(ms.depth_sensor(mi, self.geom, self.scene.lens))
        aov = mi.load_dict({"type": "aov", "aovs": "d:depth,p:position"})
        sc = self.xml_scene if self.content is None else mi.load_dict(self.content)
        out = np.array(mi.render(sc, sensor=sens, integrator=aov, spp=1, seed=0), dtype=np.float64)
        hit, pos = out[..., -4] > 0, out[..., -3:]
        z = axial_depth_m(self.geom, pos)
        return np.where(hit, z, np.inf).astype(np.float32)


def monitor_content(scene: Scene, geom: CameraGeometry) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """What the panel shows: drive levels [3, rows, cols], primaries, their band means [3, K], metadata."""
    m = scene.content
    try:
        drive, how = panel_drive(m.image, *m.resolution_px, m.transfer, _base(scene))
        primaries, prim_desc = spectra.monitor_primaries(m.primaries, m.peak_luminance_cd_m2, _base(scene),
                                                         m.white_point)
    except (DisplayImageError, spectra.SpectrumError) as e:
        raise RenderError(f"{scene.source}: {e}") from None
    matrix = spectra.band_means(primaries, np.asarray(scene.bands.edges_nm))  # [3, K]
    meta = dict(display=how, primaries=prim_desc, monitor_size_m=list(m.size_m),
                monitor_distance_m=geom.focus_distance_m if scene.lens.focus_distance_m is None else None,
                band_matrix=matrix.tolist())
    return drive, primaries, matrix, meta


def _base(scene: Scene) -> Path:
    return Path(scene.source).resolve().parent


def _passes(spp: int, path: str) -> tuple[int, int]:
    """(passes, spp per pass): at least two passes (to measure noise) once spp >= 2."""
    if spp < 2:
        return 1, 1
    n = max(2, math.ceil(spp / PASS_SPP[path]))
    return n, math.ceil(spp / n)


def estimate_spp(job: _Job, target: float, seed: int) -> tuple[int, float]:
    """spp for a relative noise `target`, from two pilot passes; also the pilot's noise."""
    pilot_spp = job.sample_count(PILOT_SPP)
    _, noise = job.render_all(pilot_spp, 2, seed, pilot=True)  # noise of the mean: 2·pilot_spp samples
    if noise is None or noise == 0:
        return 1, 0.0
    spp = math.ceil(2 * pilot_spp * (noise / target) ** 2)
    if spp > MAX_SPP:
        warnings.warn(f"noise target {target} needs {spp} spp; capped at {MAX_SPP}", RuntimeWarning, stacklevel=2)
    return int(min(max(spp, 1), MAX_SPP)), noise


def _grid_meta(scene: Scene, geom: CameraGeometry, edges: np.ndarray, depth) -> dict:
    """What every render path records about its grid, bands, units, camera and depth."""
    r = scene.render
    return {"band_edges_nm": edges.tolist(), "band_names": band_names(edges),
            "units": "band-mean radiance, W sr^-1 m^-2 nm^-1, pixel-area mean (box filter)",
            "camera": geom.describe(), "lens": vars(scene.lens), "sensor": vars(scene.sensor),
            "supersample": r.supersample, "margin_um": r.margin_um,
            "depth": "axial distance along the optical axis, m, at pixel centres; inf = no surface"
            if depth is not None
            else ("not rendered: the monitor is a plane at camera.focus_distance_m"
                  if isinstance(scene.content, Monitor) else "not rendered")}


def render_analytic(scene: Scene) -> BandImage:
    """The monitor's exact pixel-area means (render.analytic): no Monte Carlo, no Mitsuba, no noise."""
    t0 = time.perf_counter()
    g = camera_geometry(scene)
    drive, _, matrix, content_meta = monitor_content(scene, g)
    rgb = monitor_area_means(g, scene.content.size_m, drive)
    del drive  # 200 MB at 3840 × 2160
    r = scene.render
    depth = monitor_depth_m(g, scene.content.size_m) if r.depth else None
    edges = np.asarray(scene.bands.edges_nm)
    meta = {
        "scene": scene.source, "content": scene.content_type, "render_path": "analytic", "variant": None,
        "backend": "numpy", "backend_reason": "exact pixel-area means of the panel (render.analytic); no Monte Carlo",
        "spp": None, "passes": 0, "spp_per_pass": None, "seed": r.seed, "sampler": None,
        "spp_from_noise_target": r.noise, "pilot_noise_rel": None, "pilot_spp": None, "noise_rel": 0.0,
        "max_depth": None, "bands_per_render": None,
        **_grid_meta(scene, g, edges, depth), "seconds": None, **content_meta}
    image = BandImage.of_primaries(rgb, matrix, edges, g.pitch_um, g.margin_px, depth, meta)
    meta["seconds"] = round(time.perf_counter() - t0, 3)
    return image


def render_scene(scene: Scene, progress: bool = True) -> BandImage:
    """Render `scene` to a :class:`BandImage` (see the module docstring for the paths and units)."""
    t0 = time.perf_counter()
    path = choose_path(scene)
    if path == "analytic":
        return render_analytic(scene)
    job = _Job(resolve_xml_camera(scene), path)  # unchanged when resolved already (or not XML)
    r = job.scene.render
    pilot = None
    spp = r.spp
    if spp is None:
        spp, pilot = estimate_spp(job, r.noise, r.seed)
    n_pass, pass_spp = _passes(spp, path)
    pass_spp = job.sample_count(pass_spp)
    variant = job.backend.variant("rgb" if path == "rgb_matrix" else "spectral")
    bar = tqdm(total=n_pass * len(job.groups), desc=f"render ({path}, {variant})", unit="pass",
               disable=not progress, leave=False)
    means, noise = job.render_all(pass_spp, n_pass, r.seed, bar=bar)
    bar.close()
    planes = means[0] if path == "rgb_matrix" else None  # the drive-weighted RGB: bands Σ_c M_ck r_c (of_primaries)
    bands = None if path == "rgb_matrix" else np.concatenate(means, 0)
    del means
    want_depth = r.depth if r.depth is not None else not isinstance(job.scene.content, Monitor)
    depth = job.depth() if want_depth else None
    g = job.geom
    meta = {
        "scene": job.scene.source, "content": job.scene.content_type, "render_path": path,
        "variant": variant,
        "backend": job.backend.kind, "backend_reason": job.backend.reason,
        "spp": n_pass * pass_spp, "passes": n_pass, "spp_per_pass": pass_spp, "seed": r.seed, "sampler": r.sampler,
        "pass_seeds": "SeedSequence([seed, group, pass]).generate_state(1)[0]",
        "spp_from_noise_target": r.noise, "pilot_noise_rel": pilot, "pilot_spp": 2 * PILOT_SPP if pilot else None,
        "noise_rel": noise, "max_depth": job.max_depth,
        "bands_per_render": r.bands_per_render if path == "spectral" else None,
        **_grid_meta(job.scene, g, job.edges, depth), "seconds": None, **job.meta,
    }
    meta["seconds"] = round(time.perf_counter() - t0, 3)
    if path == "rgb_matrix":  # bands = Σ_c M_ck r_c of the rendered planes: kept (BandImage.of_primaries)
        return BandImage.of_primaries(planes, job.matrix, job.edges, g.pitch_um, g.margin_px, depth, meta)
    return BandImage(bands=bands.astype(np.float32), edges_nm=job.edges, pitch_um=g.pitch_um, margin_px=g.margin_px,
                     depth_m=depth, meta=meta, primaries_matrix=job.matrix)
