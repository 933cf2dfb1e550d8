"""Gap study: the size of each effect beyond the paper's model, and whether any makes DeP on the real
P-OLED 6–10 dB worse than on ours (issue 29).

    udc-render study gap --out DIR [--quick] [--images FILES]

The paper's DeP scored 28.50 dB on its real T-OLED and 16.97 dB on its real P-OLED (l.380, paper protocol).
Ours scores far higher on the P-OLED. Each effect of the physical profile (gap_effects.EFFECTS: the
display-to-lens distance, defect pixels, fixed-pattern noise, the diffraction far field, stray light,
the averaged ground truth, aberrations) is switched on alone over a bare base (the physical profile with
every effect off), and all together (the physical profile as shipped), beside the paper profile (its
synthesis as printed); the DeP candidates (gap_effects.DEP_VARIANTS: the exact kernel, a γ error, BM3D
where installed) restore the shipped profile's captures.

Per row, display and image, against the row's own ground truth, in the paper protocol (linear, [0, 1] of
the white level; udc_render.metrics, restore.metrics.paper_metrics):
- level: the ground truth's mean, a fraction of the white level. The paper protocol's PSNR moves with it
  (a quarter of the exposure lifts a P-OLED input from 19.9 to 31.6 dB), so it is stated beside each PSNR.
  Our exposure puts the monitor's white at pipeline.EXPOSURE_FILL = 0.8 of the full well through glass at
  gain 1: the paper's level, where glass captures "avoid saturation" with no gain at 125 ms (l.210–212);
- input PSNR: the packed RAW capture against the ground truth's RGGB samples;
- DeP PSNR: restore.dep with the paper's computed PSF (its recipe at 640 / 520 / 450 nm at the packed pitch,
  restore.known 'paper') and the γ that made the capture without the effect (optics.gamma: what a
  calibration of the bare model gives; the paper profile: its γ);
- for an effect row, against the base row's capture of the same item and noise seed: the capture PSNR
  between the two (packed RAW) and the share of light moved, Σ|c_on − c_off| / Σ c_off over the noise-free
  packed captures (Effect.compare: over the recorded ones for an effect on the recorded values alone, such
  as defect pixels; over the ground truths for an effect on the ground truth alone).

Content at the paper's level of detail: its DIV2K test photographs were 2K images shown on the 4K monitor
at about one image pixel per sensor pixel (l.231). Rows are scored on colour dead leaves
(pattern:dead_leaves_colour, the test content of `udc-render results`) and on `--images` (for users with
DIV2K); the built-in photographs (300–640 px, enlarged 4–7× on the monitor: far smoother) are reported
apart. ``quick``: one dead-leaves image and one photograph at 512 × 256 px.

An image's noise (the synthesis's item, pipeline.noise_seed) and DeP's sampler come from its identity (a file's
bytes, a spec as written: image_identity, image_item), not its place in --images. The study resumes: each
finished image's rows go to rows_full.jsonl (rows_quick.jsonl) in the output folder with the fingerprint of the
settings that made them (every setup, effect and DeP candidate, the image's identity: entry_fingerprint), and a
new run reuses an image's rows only under the same fingerprint; the others are recomputed, and the run says so
(studies.fingerprint). The code is not in the fingerprint: delete the file after changing the code.
"""
from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from restore.dep import dep_restore
from restore.metrics import paper_metrics
from udc_render.io.files import save_text
from udc_render.metrics import psnr_db
from udc_render.optics.gamma import display_gamma
from udc_render.scene.geometry import psf_lens
from udc_render.scene.overrides import with_overrides
from udc_render.sensor import pack_rggb, rgb_to_rggb
from udc_render.streams import seed_sequence, stream
from udc_render.studies.fingerprint import FIELD, digest, file_digest, stale_note
from udc_render.studies.gap_effects import DEP_VARIANTS, EFFECTS
from udc_render.studies.gap_report import write_report

DEAD_LEAVES = ("pattern:dead_leaves_colour:101", "pattern:dead_leaves_colour:102")
PHOTOGRAPHS = ("builtin:astronaut",)
FULL = {"sensor_px": (2048, 1024), "content": DEAD_LEAVES, "photographs": PHOTOGRAPHS}
QUICK = {"sensor_px": (512, 256), "content": DEAD_LEAVES[:1], "photographs": PHOTOGRAPHS[:1]}
DISPLAYS = ("toled", "poled")
GAP_SEED = 0  # the seed of every image's noise and DeP streams (image_item)
LOG_VERSION = 2  # 2: a log entry has the image's identity and a fingerprint (entries without one are recomputed)


@dataclass(frozen=True)
class Setup:
    """What a row synthesises with: the synthesis config, the displays (with their distance) and the scene."""
    cfg: object  # pipeline.SynthConfig
    displays: tuple  # optics.displays.Display, one per DISPLAYS
    scene: object  # scene.Scene


@dataclass
class Shot:
    """One capture of one item: the packed RAW and its noise-free twin in [0, 1] of the white level, and gt."""
    packed: np.ndarray
    clean: np.ndarray
    gt: np.ndarray
    gamma_rggb: np.ndarray
    synth_s: float


def packed_unit(capture, clean: bool = False) -> np.ndarray:
    """A capture's packed RAW (or its noise-free mosaic, packed) in [0, 1] of the white level."""
    s = capture.params["sensor"]
    dn = pack_rggb(capture.clean_dn) if clean else capture.packed_dn
    black, white = s["black_level_dn"], s["white_level_dn"]
    return ((dn.astype(np.float32) - black) / (white - black)).astype(np.float32)


_RENDERS: dict = {}


def render(scene):
    """The scene's render, once per process (every row of one image shares it; the lens's aberrations act
    on the kernels, not on the pinhole render, so they do not key it)."""
    from udc_render.render import render_scene
    key = replace(scene, lens=replace(scene.lens, zernike_waves=()))
    if key not in _RENDERS:
        if len(_RENDERS) > 2:
            _RENDERS.clear()
        _RENDERS[key] = render_scene(key)
    return _RENDERS[key]


def shoot(setup: Setup, display, item: int) -> Shot:
    """Synthesise `display`'s capture of setup.scene (item seeds the noise) and the γ that made it."""
    from udc_render.optics.displays import PAPER_GAMMA
    from udc_render.pipeline import plan_kernels, synthesize
    band_image = render(setup.scene)
    t0 = time.perf_counter()
    kernels = plan_kernels(setup.scene, [display], setup.cfg)
    res = synthesize(band_image, setup.scene, [display], setup.cfg, item=item, kernels=kernels)
    cap = res.captures[display.name]
    if setup.cfg.form == "per_channel":
        gamma = PAPER_GAMMA[display.name]
    else:
        gamma = display_gamma(display, kernels.band[display.name], kernels.band["glass"], band_image.edges_nm,
                              setup.cfg.sensor.camera, band_image.white_bands())
    return Shot(packed_unit(cap), packed_unit(cap, clean=True), res.gt, np.array(rgb_to_rggb(gamma), float),
                time.perf_counter() - t0)


def dep_kernels(display, scene, cfg, source: str = "paper") -> np.ndarray:
    """DeP's RGGB kernels of `display` at the packed pitch (restore.known: 'paper' or 'exact')."""
    from restore.known import packed_channel_kernels, packed_paper_kernels, rggb_kernels
    from udc_render.pipeline import plan_kernels
    size = (plan_kernels(scene, [display], cfg).grid.kernel_size_px // 2) | 1
    lens, pitch = psf_lens(scene), float(scene.sensor.pitch_um)
    if source == "paper":
        return rggb_kernels(packed_paper_kernels(display.layout, lens, pitch, size, cfg.use_cache))
    return rggb_kernels(packed_channel_kernels(display.layout, lens, cfg.sensor.camera, pitch, size, cfg.use_cache))


def score(shot: Shot, kernels: np.ndarray, item: int, denoiser: str = "nlm", gamma_scale: float = 1.0) -> dict:
    """Level, input PSNR and DeP PSNR of one shot (module doc)."""
    t0 = time.perf_counter()
    dep = dep_restore(shot.packed, shot.gamma_rggb * gamma_scale, kernels, denoiser=denoiser,
                      rng=stream(GAP_SEED, "gap dep", item))
    return {"level": float(shot.gt.mean()), "input_db": paper_metrics(None, shot.gt, shot.packed)["psnr_db_paper"],
            "dep_db": paper_metrics(dep.rgb, shot.gt)["psnr_db_paper"], "dep_s": time.perf_counter() - t0,
            "synth_s": shot.synth_s}


def versus(on: Shot, off: Shot, compare: str = "clean") -> dict:
    """Capture PSNR between an effect's shot and the base's, and the share of light it moves (module doc):
    over the noise-free captures ('clean'), the recorded ones ('packed') or the ground truths ('gt')."""
    a, b = getattr(on, compare), getattr(off, compare)
    moved = float(np.abs(a.astype(np.float64) - b).sum() / max(np.abs(b.astype(np.float64)).sum(), 1e-30))
    return {"capture_vs_base_db": psnr_db(on.packed, off.packed), "light_moved": moved}


def base_setups(sensor_px: tuple[int, int]) -> dict[str, Setup]:
    """The paper profile, the shipped physical profile and the bare base (every effect off)."""
    from udc_render.optics.displays import load_displays
    from udc_render.pipeline import SynthConfig
    from udc_render.profiles import resolve_profile
    from udc_render.studies.realism_paper import default_scene
    scene = default_scene(sensor_px)
    out = {}
    for profile in ("paper", "physical"):
        cfg, displays = resolve_profile(profile, SynthConfig(), load_displays(",".join(DISPLAYS)))
        by_name = {d.name: d for d in displays}
        out[profile] = Setup(cfg, tuple(by_name[n] for n in DISPLAYS), scene)
    bare = out["physical"]
    for e in EFFECTS:
        bare = e.switch(bare, False)
    out["bare"] = bare
    return out


def with_image(setup: Setup, image: str) -> Setup:
    return replace(setup, scene=with_overrides(setup.scene, image=image))


def image_identity(image: str) -> str:
    """What an image is, wherever it stands in --images or on disk: a file by the sha256 of its bytes, a spec
    (pattern:…, builtin:…) as written."""
    return f"sha256:{file_digest(image)}" if Path(image).is_file() else image


def image_item(identity: str) -> int:
    """The item that seeds an image's capture noise (pipeline.noise_seed) and its DeP sampler (score): the first
    word of the named stream (GAP_SEED, 'gap', identity). It was the image's position: reordering --images
    changed every image's noise."""
    return int(seed_sequence(GAP_SEED, "gap", identity).generate_state(1)[0])


def dep_variants(content: str, rank: int) -> list:
    """The DeP candidates run on an image of `content` at place `rank` in its content group."""
    return [v for v in DEP_VARIANTS if v.available() and (v.images is None or rank < v.images)
            and (v.content is None or v.content == content)]


def describe_setup(setup: Setup) -> dict:
    """What a setup synthesises with, as JSON values (the checkout's path and the kernel cache left out)."""
    cfg = {k: v for k, v in asdict(setup.cfg).items() if k not in ("use_cache", "kernel_cache")}
    scene = {k: v for k, v in asdict(setup.scene).items() if k != "source"}
    return {"cfg": cfg, "displays": [d.describe() for d in setup.displays], "scene": scene}


def settings_fingerprint(setups: dict) -> str:
    """digest of every setup the rows synthesise with: the profiles, the bare base and each effect on."""
    described = {k: describe_setup(s) for k, s in setups.items()}
    effects = {e.name: [e.compare, describe_setup(e.switch(setups["bare"], True))] for e in EFFECTS}
    return digest({"version": LOG_VERSION, "displays": DISPLAYS, "setups": described, "effects": effects})


def entry_fingerprint(settings: str, identity: str, content: str, rank: int) -> str:
    """The fingerprint of one image's rows: the settings', the image's identity, its content group and item,
    and the DeP candidates it runs."""
    return digest({"settings": settings, "image": identity, "content": content, "item": image_item(identity),
                   "dep": [asdict(v) for v in dep_variants(content, rank)]})


def rows_for_image(image: str, content: str, item: int, setups: dict, progress_bar=None, rank: int = 0) -> list[dict]:
    """Every row (module doc) for one image, both displays; `item` seeds its noise (image_item); `rank`: the
    image's place in its content group."""
    rows = []
    for di, name in enumerate(DISPLAYS):
        def at(setup):
            return with_image(setup, image), setup.displays[di]

        kern = dep_kernels(setups["physical"].displays[di], setups["physical"].scene, setups["physical"].cfg)
        shots = {}
        for key in ("paper", "bare", "physical"):
            s, d = at(setups[key])
            shots[key] = shoot(s, d, item)
        common = {"display": name, "image": image, "content": content}
        rows.append({**common, "row": "paper profile", "kind": "profile", **score(shots["paper"], kern, item)})
        rows.append({**common, "row": "physical, every effect off", "kind": "base", **score(shots["bare"], kern, item)})
        for e in EFFECTS:
            s, d = at(e.switch(setups["bare"], True))
            shot = shoot(s, d, item)
            rows.append({**common, "row": f"{e.name} on", "kind": "effect", "effect": e.name,
                         **score(shot, kern, item), **versus(shot, shots["bare"], e.compare)})
            if progress_bar is not None:
                progress_bar.update()
        rows.append({**common, "row": "physical (every default)", "kind": "profile",
                     **score(shots["physical"], kern, item),
                     **versus(shots["physical"], shots["bare"])})
        for v in dep_variants(content, rank):
            k = kern if v.kernels == "paper" else dep_kernels(setups["physical"].displays[di], setups["physical"].scene,
                                                               setups["physical"].cfg, v.kernels)
            rows.append({**common, "row": f"DeP: {v.name}", "kind": "dep", "effect": v.name,
                         **score(shots["physical"], k, item, v.denoiser, v.gamma_scale)})
    return rows


def read_log(log: Path) -> list[dict]:
    """The entries of an earlier run's log (one JSON line per finished image: its rows, seconds, identity and
    fingerprint; a torn last line is ignored): the study resumes image by image."""
    entries = []
    if log.is_file():
        for line in log.read_text().splitlines():
            try:
                entries.append(json.loads(line))
            except json.JSONDecodeError:
                continue
    return entries


def read_rows(log: Path) -> dict[str, list[dict]]:
    """{image: its rows} of read_log (an image's last entry)."""
    return {entry["image"]: entry["rows"] for entry in read_log(log)}


def logged(log: Path, plan: list[tuple]) -> tuple[dict, int]:
    """({fingerprint: entry} of the log's entries that `plan`'s images can reuse, the number of logged rows of
    plan's images made under another fingerprint or none). Those stale entries leave the log."""
    entries = read_log(log)
    wanted = {fp for *_, fp in plan}
    images = {image for image, *_ in plan} | {identity for _, _, identity, *_ in plan}
    stale = [e for e in entries if e.get(FIELD) not in wanted and (e.get("identity") or e["image"]) in images]
    if stale:
        save_text(log, "".join(json.dumps(e) + "\n" for e in entries if not any(e is x for x in stale)))
    return {e[FIELD]: e for e in entries if e.get(FIELD) in wanted}, sum(len(e["rows"]) for e in stale)


def run_study(out_dir, quick: bool = False, images: tuple[str, ...] = (), progress: bool = True) -> list[dict]:
    """Write study_gap.csv, .md and .png into out_dir (gap_report); returns the rows."""
    c = QUICK if quick else FULL
    setups = base_setups(c["sensor_px"])
    content = ([(i, "dead leaves") for i in c["content"]] + [(i, "--images") for i in images]
               + [(i, "built-in photographs (enlarged)") for i in c["photographs"]])
    settings, plan = settings_fingerprint(setups), []
    for n, (image, kind) in enumerate(content):
        identity, rank = image_identity(image), sum(1 for _, k in content[:n] if k == kind)
        plan.append((image, kind, identity, rank, entry_fingerprint(settings, identity, kind, rank)))
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    log = Path(out_dir) / f"rows_{'quick' if quick else 'full'}.jsonl"
    done, stale = logged(log, plan)
    if note := stale_note("study gap", stale, log):
        print(note)
    bar = tqdm(total=len(content) * len(DISPLAYS) * len(EFFECTS), desc="study gap", unit="row", disable=not progress)
    rows, seconds = [], 0.0
    for image, kind, identity, rank, fp in plan:
        if fp in done:  # scored by an earlier run with the same settings
            rows += [{**r, "image": image} for r in done[fp]["rows"]]
            seconds += done[fp].get("seconds", 0.0)
            bar.update(len(DISPLAYS) * len(EFFECTS))
            continue
        t0 = time.perf_counter()
        new = rows_for_image(image, kind, image_item(identity), setups, bar, rank)
        took = time.perf_counter() - t0
        with open(log, "a") as f:
            f.write(json.dumps({"image": image, "identity": identity, FIELD: fp, "rows": new, "seconds": took}) + "\n")
        rows += new
        seconds += took
    bar.close()
    write_report(Path(out_dir), rows, setups, c, seconds, quick)  # the images' seconds, over every resume
    return rows
