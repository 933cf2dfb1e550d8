"""The online degradation's cost against a training step (issue 31: it may slow training by at most 10 %).

    .venv/bin/python benchmarks/bench_degrade.py [--crop-px 256] [--batch 4] [--kernel-px 513] [--rank 4]
        [--frame 2048,1024] [--repeats 7] [--threads N] [--bank DIR] [--device cpu|cuda]

Per batch of `--batch` crops of `--crop-px` (each with the kernel's half-width of scene around it, as
`udc-render train --degrade online` takes them): the degradation (restore.degrade.Degrader.degrade_batch, crop
by crop and as one batch, float32, a generator per crop) through a d = 0 panel (one kernel per channel) and a
d > 0 panel (the rank-r field basis with the exact power map; the map of the frame made once beforehand, timed
apart), against one Adam step of the paper's UNet (restore.models.UNET_CONFIG) on that batch, float32 and bf16
autocast (the cpu budget's), at torch's thread count (and others with --step-threads). The Degrader's ops run
on --degrade-threads threads (restore.degrade.DEGRADE_THREADS, 1 by default: see the table). The timings
alternate between the rows, repeat by repeat, so that a load that comes and goes hits them alike; the table
gives the medians, and each degradation's ratio to each step (medians, and in brackets the fastest repeats').

--train: training itself, steps of the UNet (--autocast bf16|fp32) on batches degraded on the fly (restore.online
.OnlineBatches: crops of two clean 2048 × 1024 images through the panels, drawn per crop) with the degradation in
this process (workers 0) and in a DataLoader worker process (1), crop by crop on the CPU; on a GPU workers 1 is a
thread on its own stream and a batch is degraded as one (the Degrader's defaults). Against the same steps on batches
made beforehand, the three runs alternating for --rounds rounds; the slowdown is the ratio of the median step times
(each run's first step left out: a worker's start) less one, in wall time and in this process's CPU time (the
degradation's CPU where it runs in this process; a load from other jobs stretches the wall time). --device cuda: the
steps and the degradation on the GPU (float32 panels), timed to a synchronize after each step. --capture-draws adds
a run of workers 1 in which every crop draws its own sensor and exposure (restore.captures, `udc-render train
--capture-draws default`).

Without --bank the panels are synthetic with the shapes of the default bank (kernels of --kernel-px, a T-OLED series
of 453 × 200 orders, 4 × 4 phases, Poisson noise, defects, FPN): the cost depends on the shapes, not on the values.
With --bank DIR its first d = 0 and first d > 0 panel are timed. --results-bank toled|poled: the results run's own
bank (`udc-render results --budget cpu`'s UNet (randomized) row: restore.studies.random_row.bank_plan), its first
--bank-panels panels (1: random_000) made once in out/bench_degrade/banks (resumable; random_000 took 4.7 min on the
loaded 2-core machine) and all of them drawn from, as that run's crops are.

--train --autocast both: the fp32 and the bf16 step in the same run, their rounds interleaved. The step is the
results run's (restore.train.train_step with its gradient clip, 0.5, and lr 2e-4: BUDGETS['cpu']).

--regions 1,2,3,4: what sharing one degraded region between t × t crops would save (a design not built: the
10 % bound's candidate). Per panel, one region of t·crop px with its margins degraded as one crop on one thread,
alternating t repeat by repeat; the table gives the median time per crop of --crop-px and its ratio to t = 1.
"""
from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
import torch

from restore.captures import load_capture_draws
from restore.degrade import Degrader, WideSource, cpu_threads
from restore.losses import loss_fn
from restore.models import UNET_CONFIG, build_model
from restore.online import CleanImage, OnlineBatches
from restore.train import TrainSettings, train_step
from udc_render.dataset.bank import Bank, Panel, PanelField, read_bank
from udc_render.sensor import DefectConfig, FpnConfig, SensorConfig


def synthetic_panels(kernel_px: int, rank: int) -> list[Panel]:
    """A d = 0 and a d > 0 panel with the default bank's shapes (module doc)."""
    rng = np.random.default_rng(0)
    k = rng.random((3, kernel_px, kernel_px)).astype(np.float32)
    k /= k.sum(axis=(1, 2), keepdims=True)
    sensor = SensorConfig(form="per_channel", gain=6.0, gamma_rggb=(0.97 / 6,) * 4, exposure_s=0.031)
    flat = Panel("d0", k, 1.55, (0.97,) * 3, sensor, DefectConfig(), FpnConfig(), None, {})
    live = tuple((j, i) for j in range(4) for i in range(4))
    series = np.zeros((3, 453, 200), complex)
    series[:, 226, 0] = 1.0
    series[:, :, 1:] = 1e-4 * (rng.standard_normal((3, 453, 199)) + 1j * rng.standard_normal((3, 453, 199)))
    field = PanelField(np.repeat(k[:, None], rank, axis=1) / rank, rng.random((3, 16, rank)), live,
                       np.arange(4) * 317 / 4, np.arange(4) * 317 / 4, (True, True), (317.0, 317.0), 2.0, 6014.0,
                       np.ones((3, 4, 4)), series)
    return [flat, Panel("d2", k, 1.55, (0.97,) * 3, sensor, DefectConfig(), FpnConfig(), field, {})]


def results_bank(display: str, count: int) -> Path:
    """The first `count` panels of the results run's bank for `display` (restore.studies.random_row.bank_plan at
    BUDGETS['cpu']: the same specs and settings, so panel random_<i> is that run's), made or finished in
    out/bench_degrade/banks/random_<display>; its folder."""
    from restore.studies.budgets import BUDGETS
    from restore.studies.random_row import bank_plan
    from udc_render.dataset.bank_make import make_bank
    plan = bank_plan(Path("out/bench_degrade"), BUDGETS["cpu"], display)
    t0 = time.perf_counter()
    made = make_bank(plan.folder, plan.specs[:count], plan.settings, plan.kernel_px, progress=False)["made"]
    if made:
        print(f"made {made} panel(s) of the results bank in {plan.folder}: {time.perf_counter() - t0:.0f} s")
    return plan.folder


def chosen_panels(a) -> list[Panel]:
    """The panels timed: --results-bank's all, --bank's first d = 0 and d > 0, or the synthetic pair."""
    if a.results_bank:
        return read_bank(a.bank).panels
    return bank_panels(a.bank) if a.bank else synthetic_panels(a.kernel_px, a.rank)


def bank_panels(folder) -> list[Panel]:
    panels = read_bank(folder).panels
    flat = next((p for p in panels if p.field is None), None)
    banded = next((p for p in panels if p.field is not None), None)
    return [p for p in (flat, banded) if p is not None]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--crop-px", type=int, default=256)
    ap.add_argument("--batch", type=int, default=4)
    ap.add_argument("--kernel-px", type=int, default=513)
    ap.add_argument("--rank", type=int, default=4)
    ap.add_argument("--frame", default="2048,1024", help="W,H of the clean images")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--threads", type=int, help="torch threads [torch's default]")
    ap.add_argument("--bank", help="time this bank's panels instead of the synthetic ones")
    ap.add_argument("--results-bank", choices=("toled", "poled"),
                    help="the results run's bank of this display, its first --bank-panels panels (module doc)")
    ap.add_argument("--bank-panels", type=int, default=1, help="--results-bank: how many of its panels [1]")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--degrade-threads", default="1,0",
                    help="the Degrader's CPU threads to time, comma-separated (0: torch's setting) [1,0]")
    ap.add_argument("--step-threads", default="0",
                    help="the UNet step's CPU threads to time, comma-separated (0: torch's setting) [0]")
    ap.add_argument("--train", action="store_true", help="time training steps on online batches (module doc)")
    ap.add_argument("--steps", type=int, default=6, help="--train: steps per run [6]")
    ap.add_argument("--rounds", type=int, default=3, help="--train: rounds of the three runs [3]")
    ap.add_argument("--autocast", choices=("bf16", "fp32", "both"),
                    help="the step's precision [--train: bf16; else both] (bf16 is 13× slower where it is emulated)")
    ap.add_argument("--capture-draws", action="store_true", help="--train: add a run with a capture per crop")
    ap.add_argument("--regions", help="t values, comma-separated: time t × t crops sharing one region (module doc)")
    a = ap.parse_args()
    if a.results_bank:
        a.bank = str(results_bank(a.results_bank, a.bank_panels))
    if a.train:
        a.autocast = a.autocast or "bf16"
        return train_runs(a)
    if a.regions:
        return region_runs(a)
    if a.threads:
        torch.set_num_threads(a.threads)
    dev = torch.device(a.device)
    w, h = (int(v) for v in a.frame.split(","))
    panels = chosen_panels(a)
    degraders = {n: Degrader(panels, dev, threads=n or None) for n in (int(t) for t in a.degrade_threads.split(","))}
    deg = next(iter(degraders.values()))
    m, c = deg.margin_px, a.crop_px
    t0 = time.perf_counter()
    for i, p in enumerate(panels):
        deg.power_frame(i, (h, w))
    power_s = time.perf_counter() - t0
    for other in degraders.values():
        other._power = deg._power  # the same maps, made once
    crops = torch.rand(a.batch, 3, c + 2 * m, c + 2 * m)
    source = WideSource("bench", torch.rand(3, h, w, device=dev))  # a bank panel's far field and haze see it
    origins = [(2 * int(v), 2 * int(u)) for v, u in zip(np.linspace(0, (h - c) // 2, a.batch),
                                                        np.linspace(0, (w - c) // 2, a.batch))]
    model = build_model(UNET_CONFIG).to(dev, memory_format=torch.channels_last)
    opt = torch.optim.Adam(model.parameters(), lr=1e-4)
    loss_of = loss_fn("l1")
    x = torch.rand(a.batch, 4, c // 2, c // 2, device=dev).to(memory_format=torch.channels_last)
    y = torch.rand(a.batch, 3, c, c, device=dev).to(memory_format=torch.channels_last)
    settings = {name: TrainSettings(model=UNET_CONFIG, display="bench", autocast=ac)
                for name, ac in (("fp32", None), ("bf16", "bf16")) if a.autocast in (None, "both", name)}
    step_threads = [int(t) or torch.get_num_threads() for t in a.step_threads.split(",")]

    def sync():
        if dev.type == "cuda":
            torch.cuda.synchronize()

    def degrade(d, i, batched):
        d.batched = batched
        d.degrade_batch(crops, [i] * a.batch, [((h, w), o) for o in origins],
                        [torch.Generator(dev).manual_seed(b) for b in range(a.batch)], sources=[source] * a.batch)

    rows = {f"degrade {p.name} ({'d > 0, rank ' + str(p.field.rank) if p.field else 'd = 0'}), "
            f"{n or torch.get_num_threads()} thread{'s' if (n or torch.get_num_threads()) > 1 else ''}, "
            f"{'one batch' if batched else 'crop by crop'}": (lambda d=d, i=i, batched=batched: degrade(d, i, batched))
            for n, d in degraders.items() for i, p in enumerate(panels) for batched in (False, True)}
    def step(s, n):
        with cpu_threads(n if dev.type == "cpu" else None):
            train_step(model, opt, x, y, loss_of, s)

    rows.update({f"UNet step {k}, {n} thread{'s' if n > 1 else ''}": (lambda s=s, n=n: step(s, n))
                 for k, s in settings.items() for n in step_threads})
    for fn in rows.values():  # warm-up: kernel spectra, FFT plans, the allocator
        fn()
    times = {k: [] for k in rows}
    for _ in range(a.repeats):
        for k, fn in rows.items():
            sync()
            t = time.perf_counter()
            fn()
            sync()
            times[k].append(time.perf_counter() - t)
    med = {k: statistics.median(v) for k, v in times.items()}
    steps = [k for k in med if k.startswith("UNet")]
    print(f"device {dev}, torch threads {torch.get_num_threads()}, batch {a.batch} × {c} px crops, margin {m} px "
          f"(kernel {2 * m + 1} px), frame {w} × {h}, {a.repeats} repeats; "
          f"{'bank ' + a.bank if a.bank else 'synthetic panels'}; power maps made once: {power_s:.2f} s")
    print("ratios: a degradation's median over a step's median (and the same for their fastest repeats)")
    print("| row | median s per batch | min | max | " + " | ".join(f"/ {s}" for s in steps) + " |")
    print("|---|---|---|---|" + "---|" * len(steps))
    for k, v in med.items():
        ratios = " | ".join(f"{v / med[s]:.3f} ({min(times[k]) / min(times[s]):.3f})" if k.startswith("degrade") else ""
                            for s in steps)
        print(f"| {k} | {v:.3f} | {min(times[k]):.3f} | {max(times[k]):.3f} | {ratios} |")


def _setup(a) -> tuple[torch.device, tuple[int, int], list[Panel]]:
    """(device, (W, H) of the clean images, the panels) of --train and --regions, torch's threads set."""
    if a.threads:
        torch.set_num_threads(a.threads)
    w, h = (int(v) for v in a.frame.split(","))
    return torch.device(a.device), (w, h), chosen_panels(a)


def region_runs(a) -> None:
    """--regions: the degradation's time per crop when t × t crops share one degraded region (module doc)."""
    dev, (w, h), panels = _setup(a)
    deg = Degrader(panels, dev, threads=1)
    for i in range(len(panels)):
        deg.power_frame(i, (h, w))
    m, c, tiles = deg.margin_px, a.crop_px, [int(t) for t in a.regions.split(",")]
    regions = {t: torch.rand(1, 3, t * c + 2 * m, t * c + 2 * m, device=dev) for t in tiles}
    source = WideSource("bench", torch.rand(3, h, w, device=dev))
    times = {(i, t): [] for i in range(len(panels)) for t in tiles}
    for r in range(a.repeats + 1):  # the first repeat makes each shape's spectra: left out
        for i in range(len(panels)):
            for t in tiles:
                t0 = time.perf_counter()
                deg.degrade_batch(regions[t], [i], [((h, w), (0, 0))], [torch.Generator(dev).manual_seed(r)],
                                  sources=[source])
                if dev.type == "cuda":
                    torch.cuda.synchronize()
                if r:
                    times[(i, t)].append(time.perf_counter() - t0)
    print(f"| panel | crops per region | region px | median ms per region | ms per {c}-px crop | / t = {tiles[0]} |")
    print("|---|---|---|---|---|---|")
    for i, p in enumerate(panels):
        base = statistics.median(times[(i, tiles[0])]) / tiles[0] ** 2
        for t in tiles:
            med = statistics.median(times[(i, t)])
            print(f"| {p.name} | {t} × {t} | {t * c} | {med * 1e3:.0f} | {med / t / t * 1e3:.1f} | "
                  f"{med / t / t / base:.2f} |")


def train_runs(a) -> None:
    """--train (module doc)."""
    dev, (w, h), panels = _setup(a)
    bank = Bank(Path("."), {}, panels)
    rng = np.random.default_rng(0)
    images = [CleanImage(f"noise {i}", rng.random((3, h, w), dtype=np.float32)) for i in range(2)]
    precisions = ("fp32", "bf16") if a.autocast == "both" else (a.autocast,)
    settings = {p: TrainSettings(model=UNET_CONFIG, display="bench", autocast=None if p == "fp32" else "bf16",
                                 clip_grad_norm=0.5, lr=2e-4) for p in precisions}  # the results run's step
    model = build_model(UNET_CONFIG).to(dev, memory_format=torch.channels_last)
    opt = torch.optim.Adam(model.parameters(), lr=2e-4)
    loss_of = loss_fn("l1")
    c, per_image = a.crop_px, (a.steps * a.batch + 1) // 2

    def run(batches, s) -> list[tuple[float, float]]:
        """(wall s, this process's CPU s) of each step but the first, the batch's making included."""
        times, t, cpu = [], time.perf_counter(), time.process_time()
        for x, y in batches:
            train_step(model, opt, x.to(memory_format=torch.channels_last), y.to(memory_format=torch.channels_last),
                       loss_of, s)
            if dev.type == "cuda":
                torch.cuda.synchronize()
            now, now_cpu = time.perf_counter(), time.process_time()
            times.append((now - t, now_cpu - cpu))
            t, cpu = now, now_cpu
        return times[1:]
    ready = [(torch.rand(a.batch, 4, c // 2, c // 2, device=dev), torch.rand(a.batch, 3, c, c, device=dev))
             for _ in range(a.steps)]
    online = {"online, workers 0": (0, None), "online, workers 1": (1, None)}  # name: (workers, capture draws)
    if a.capture_draws:
        online["online, workers 1, a capture per crop"] = (1, load_capture_draws("default"))
    times: dict = {(p, name): [] for p in precisions for name in ("ready batches", *online)}
    for _ in range(a.rounds):  # the runs alternate, round by round
        for p, name in times:
            if name.startswith("ready"):
                times[(p, name)] += run(ready, settings[p])
            else:
                workers, captures = online[name]
                ob = OnlineBatches(images, bank, Degrader(panels, dev), c, a.batch, 0, per_image, workers, captures)
                times[(p, name)] += run(ob.epoch(0)[1], settings[p])
    print(f"device {dev}, torch threads {torch.get_num_threads()}, UNet {', '.join(precisions)}, batch {a.batch} × "
          f"{c} px, kernel {panels[0].kernel_px} px, panels {', '.join(p.name for p in panels)} (drawn per crop), "
          f"{a.rounds} rounds of {a.steps} steps per run (each run's first left out); "
          f"{'bank ' + a.bank if a.bank else 'synthetic panels'}")
    print(train_table(times))


def train_table(times: dict) -> str:
    """Markdown: per (precision, run) the steps timed, the median wall time of a step, its quartiles and its
    slowdown against the same precision's ready batches; the same for this process's CPU time (a worker process's
    is not in it), which a load from other jobs changes far less than the wall time."""
    lines = ["| step | run | steps timed | median wall s | quartiles | wall slowdown | median CPU s | quartiles | "
             "CPU slowdown |", "|---|---|---|---|---|---|---|---|---|"]
    for (p, name), v in times.items():
        cells = []
        for k in (0, 1):
            med, q = statistics.median(t[k] for t in v), statistics.quantiles([t[k] for t in v], n=4)
            ref = statistics.median(t[k] for t in times[(p, "ready batches")])
            cells.append(f"{med:.3f} | {q[0]:.3f}–{q[2]:.3f} | {med / ref - 1:+.1%}")
        lines.append(f"| {p} | {name} | {len(v)} | {' | '.join(cells)} |")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
