"""The render study's grids (FULL, QUICK), its CSV columns and its two scenes at reduced resolution."""
from __future__ import annotations

from dataclasses import dataclass, replace

from udc_render.scene import SAMPLERS, Scene, Sensor, load_scene, scenes_dir
from udc_render.scene.geometry import camera_geometry

FULL_SENSOR = (2048, 1024, 1.55)  # the scene files' sensor, for the extrapolations and the full-frame runs
REPEAT_BELOW_S = 4.0  # a sweep run is repeated (median time) only when it takes less
TARGETS = (0.05, 0.02, 0.01)  # relative errors the fits give spp and seconds for
MONITOR_TARGETS = (0.01, 0.001)  # the monitor's full-frame sampler table: 1 % and the 0.1 % of a ground truth

COLUMNS = ["scene", "path", "sampler", "variant", "spp", "spp_requested", "bands_per_render", "seconds",
           "rel_error", "noise_rel", "rel_error_net", "rel_error_xyz", "rel_error_xyz_net", "band_mean_dev",
           "err_over_noise", "role", "groups", "renders_x_spp", "sensor_px", "pitch_um", "grid_px", "seconds_min",
           "cpu_seconds", "repeats", "seed", "ref_path", "ref_spp", "ref_noise_rel", "ref_noise_xyz"]


@dataclass(frozen=True)
class Config:
    quick: bool
    repeats: int
    samplers: tuple  # the Mitsuba samplers compared (render.sampler)
    monitor_sensor: tuple  # (width_px, height_px, pitch_um)
    monitor_panel_px: tuple | None  # None: the scene's panel (3840 × 2160)
    rgb_spp: tuple  # rgb_matrix, independent sampler
    rgb_sampler_spp: tuple  # rgb_matrix, every other sampler (requested; 2 × a power of 4 is exact for ldsampler)
    exact_check_spp: int  # an ldsampler rgb_matrix render against the analytic reference (the check that it is exact)
    full_spp: tuple  # rgb_matrix per sampler at the full sensor against the analytic image there (() = none)
    spectral_bpr: tuple
    spectral_spp: tuple
    room_sensor: tuple
    room_bpr: tuple  # independent sampler
    room_budgets: tuple  # renders × spp per render, the same for every bands_per_render line and every sampler
    room_ref_bpr: int
    room_ref_spp: int
    checks: bool  # room resolution checks: noise_rel at higher resolution (no reference), per sampler


FULL = Config(quick=False, repeats=3, samplers=SAMPLERS, monitor_sensor=(512, 256, 6.2), monitor_panel_px=None,
              rgb_spp=(1, 2, 4, 8, 16, 32, 64, 128, 256), rgb_sampler_spp=(8, 32, 128, 512), exact_check_spp=1024,
              full_spp=(8, 32, 128), spectral_bpr=(4, 30), spectral_spp=(2, 8, 32), room_sensor=(128, 64, 24.8),
              room_bpr=(1, 2, 4, 8, 30), room_budgets=(16, 64, 256), room_ref_bpr=2, room_ref_spp=256, checks=True)

QUICK = Config(quick=True, repeats=1, samplers=("independent", "ldsampler"), monitor_sensor=(128, 64, 24.8),
               monitor_panel_px=(960, 540), rgb_spp=(4, 16, 64), rgb_sampler_spp=(8, 32, 128), exact_check_spp=256,
               full_spp=(), spectral_bpr=(30,), spectral_spp=(4, 16), room_sensor=(64, 32, 49.6), room_bpr=(8, 30),
               room_budgets=(8, 32, 128), room_ref_bpr=8, room_ref_spp=64, checks=False)


def study_scenes(cfg: Config) -> dict[str, Scene]:
    """The monitor and room scene files at the study's reduced resolution (same physical sensor)."""
    mon = load_scene(scenes_dir() / "monitor.toml")
    mon = replace(mon, sensor=Sensor(*cfg.monitor_sensor)).with_render(depth=False)
    if cfg.monitor_panel_px is not None:
        mon = replace(mon, content=replace(mon.content, resolution_px=tuple(cfg.monitor_panel_px)))
    room = load_scene(scenes_dir() / "room.toml")
    room = replace(room, sensor=Sensor(*cfg.room_sensor)).with_render(depth=False, path="spectral")
    return {"monitor": mon, "room": room}


def grid_px(scene: Scene) -> list[int]:
    """[width, height] of the scene's render grid (sensor plus margin) in pixels."""
    g = camera_geometry(scene)
    return [g.width_px, g.height_px]
