"""``paramlod bench --extras functions``: evaluation throughput of the built-in functions against the
device's FP32 peak.

For every built-in and SH glyph order: samples/s of positions only (kernels/common/eval.cl
``eval_throughput``, ``pl_position``) and of position + partials + normal (``eval_surface_throughput``,
``pl_surface`` then cross(du, dv) as the point renderers do), FLOPs per sample counted from the
generated OpenCL (``count_flops``), FLOP/s and the fraction of the FP32 peak. The peak is measured
with an FMA-chain kernel (``fma_ceiling``) and, where the device is in ``LANES``, also estimated from
its OpenCL info. ``before=True`` adds the same rows for the generator without the shared CSE
(``codegen_cl.lower(optimize=False)``).

FLOP counting rule (``count_flops``), on the text of the generated function after CSE:
every binary ``+ - * /`` is 1 FLOP (a mul and add the compiler contracts to one fma is still 2: the
rule counts what is computed, not instructions); unary minus is free (it folds into a sub or fma);
each math call (sqrt, rsqrt, sin, cos, exp, pow, ...) is 1 and ``sincos`` 2 (two results); comparisons,
``&&``/``||`` and the ternary select are 1 each. Parameter loads and the final float3 stores are 0.
The transcendental calls are also reported on their own (``calls``): their real cost is several FMAs,
so the fraction of the FMA peak is a lower bound of how busy the ALUs are.
"""
from __future__ import annotations

import re

import numpy as np
import pyopencl as cl
import pyopencl.array as cla

from paramlod.device import programs
from paramlod.device.context import cl_device
from paramlod.function.codegen_cl import SPLIT_V, cl_dispatch_source, cl_function_source, surface_split
from paramlod.function.programs import sample_run
from paramlod.function.registry import all_functions
from paramlod.functions.sh_glyph import make_sh_glyph

SH_ORDERS = (2, 4, 6, 8, 10, 12)
NORMAL_FLOPS = 9          # cross(du, dv): 6 mul + 3 sub
SUM_FLOPS = (2, 5)        # the benchmark kernels' own sums: 3 (positions), 6 (surface) terms
FMA_CHAINS = 64           # as kernels/bench/bench.cl fma_ceiling (16 float4)

# FP32 lanes per compute unit of devices whose OpenCL info does not say it. NVIDIA: one CU is one SM
# (Volta onwards 64 FP32 lanes, Ampere/Ada/Hopper 128 dual-issued); AMD GCN/RDNA: one CU is 64 lanes.
LANES = [
    ("nvidia", ("h100", "h200", "h800", "gh200"), 128),
    ("nvidia", ("rtx 30", "rtx 40", "rtx a", "a10", "a40", "l4", "l40", "rtx 50"), 128),
    ("nvidia", ("a100", "a30", "v100", "titan v", "rtx 20", "t4", "quadro rtx"), 64),
    ("amd", ("radeon", "gfx", "instinct", "mi"), 64),
]

_CALL_WEIGHTS = {"sincos": 2}
_TOKEN = re.compile(r"\s*(?:(?P<num>\d+\.?\d*(?:[eE][+-]?\d+)?f?|\.\d+(?:[eE][+-]?\d+)?f?)"
                    r"|(?P<name>[A-Za-z_]\w*)|(?P<op>&&|\|\||[<>=!]=|[-+*/<>?:(),\[\]&=;{}]))")
_NOT_CALLS = {"float", "float3", "int", "uint", "const", "return", "void", "inline", "__global"}


def count_flops(code: str) -> dict:
    """FLOPs (the rule in the module docstring) of OpenCL C statements: the right-hand sides of
    ``=`` and ``return`` expressions. Returns {"flops", "calls"} (calls: math-library calls)."""
    flops = calls = 0
    for stmt in code.split(";"):
        stmt = stmt.strip()
        if "=" in stmt and not re.match(r"^\s*(return\b)", stmt):
            m = re.search(r"(?<![<>=!])=(?!=)", stmt)
            stmt = stmt[m.end():]
        elif stmt.startswith("return"):
            stmt = stmt[len("return"):]
        else:
            continue
        prev = None   # kind of the previous token: "operand" after a value, else an operator
        pos = 0
        while pos < len(stmt):
            m = _TOKEN.match(stmt, pos)
            if not m:
                raise ValueError(f"count_flops: cannot read {stmt[pos:pos + 20]!r}")
            pos = m.end()
            if m.group("num"):
                prev = "operand"
            elif m.group("name"):
                name = m.group("name")
                nxt = stmt[pos:].lstrip()[:1]
                if nxt == "(" and name not in _NOT_CALLS:
                    flops += _CALL_WEIGHTS.get(name, 1)
                    calls += 1
                    prev = None
                else:
                    prev = "operand"
            else:
                op = m.group("op")
                if op in ("+", "-", "*", "/"):
                    if prev == "operand":   # binary; unary minus/deref cost nothing
                        flops += 1
                    prev = None
                elif op in ("<", ">", "<=", ">=", "==", "!=", "&&", "||", "?"):
                    flops += 1
                    prev = None
                elif op in (")", "]"):
                    prev = "operand"
                else:
                    prev = None
        if stmt.count("(") != stmt.count(")"):
            raise ValueError(f"count_flops: unbalanced parentheses in {stmt[:60]!r}")
    return {"flops": flops, "calls": calls}


def _function_text(src: str, name: str) -> str:
    start = src.index(name + "(")
    body = src.index("{", start)
    return src[body + 1:src.index("\n}\n", body)]


def function_flops(fn, optimize: bool = True) -> dict:
    """FLOPs per sample of the generated ``pl_pos`` and ``pl_surf`` of ``fn`` (without the normal)."""
    src = cl_function_source(fn, 0, optimize)
    pos = count_flops(_function_text(src, "pl_pos_0"))
    surf = count_flops(_function_text(src, "pl_surf_0"))
    return {"position": pos["flops"], "surface": surf["flops"],
            "position_calls": pos["calls"], "surface_calls": surf["calls"]}


# --- the FP32 peak ------------------------------------------------------------------------------------
def peak_from_info(info: dict) -> float | None:
    """FP32 FLOP/s from a device description: compute units x clock x FP32 lanes per unit x 2 (fma).

    ``info``: name, vendor, type ("GPU"/"CPU"), max_compute_units, max_clock_frequency (MHz),
    native_vector_width_float. GPUs: lanes from ``LANES`` (None when unknown). CPUs: one compute unit
    is a hardware thread with the native SIMD width and two FMA ports per core (x86 since Haswell),
    i.e. 2 threads share the ports of a core when SMT is on: a rough upper bound, so the measured
    ceiling is the number to trust on CPUs.
    """
    units, mhz = int(info["max_compute_units"]), float(info["max_clock_frequency"])
    if units <= 0 or mhz <= 0:
        return None
    name, vendor = str(info.get("name", "")).lower(), str(info.get("vendor", "")).lower()
    if "CPU" in str(info.get("type", "")).upper():
        lanes = max(1, int(info.get("native_vector_width_float", 1))) * 2
        return units * mhz * 1e6 * lanes * 2
    for v, keys, lanes in LANES:
        if v in vendor and any(k in name for k in keys):
            return units * mhz * 1e6 * lanes * 2
    return None


def device_info(dev: cl.Device) -> dict:
    return {"name": dev.name, "vendor": dev.vendor, "type": cl.device_type.to_string(dev.type),
            "max_compute_units": dev.max_compute_units, "max_clock_frequency": dev.max_clock_frequency,
            "native_vector_width_float": dev.native_vector_width_float}


def fma_ceiling_reference(n: int, steps: int, a: float, b: float) -> np.ndarray:
    """numpy twin of fma_ceiling (float32; without fused rounding, so equal to a few ulps)."""
    gid = np.arange(n, dtype=np.uint32)
    j = np.arange(FMA_CHAINS // 4)
    lane = (np.arange(4)[None, :] + 4 * (j % 4)[:, None]).astype(np.float32) * np.float32(1e-4)
    x = ((gid & 255).astype(np.float32)[:, None, None] * np.float32(1e-3) + lane[None]
         + (j // 4).astype(np.float32)[None, :, None] * np.float32(1e-5)).astype(np.float32)
    a, b = np.float32(a), np.float32(b)
    for _ in range(steps):
        x = x * a + b
    s = np.zeros((n, 4), np.float32)
    for k in range(x.shape[1]):
        s += x[:, k]
    return ((s[:, 0] + s[:, 1]) + (s[:, 2] + s[:, 3])).astype(np.float32)


def _fma_kernel():
    return programs.kernel("fma_ceiling", ["bench/bench.cl"])


def measured_peak(n: int | None = None, steps: int = 512, repeats: int = 3) -> float:
    """FP32 FLOP/s of the fma_ceiling kernel (best of ``repeats``)."""
    dev = cl_device()
    q = dev.queue
    if n is None:
        n = 1 << (14 if "CPU" in cl.device_type.to_string(q.device.type).upper() else 18)
    out = cla.empty(q, n, np.float32)
    k = _fma_kernel()
    # a slightly contracting map keeps values finite over any number of steps
    best = None
    for r in range(repeats + 1):
        evt = k(q, (n,), None, np.uint32(steps), np.float32(0.999), np.float32(1e-3), out.data)
        evt.wait()
        if r:
            t = (evt.profile.end - evt.profile.start) * 1e-9
            best = t if best is None else min(best, t)
    return n * steps * FMA_CHAINS * 2 / best


# --- throughput -----------------------------------------------------------------------------------
def _time(k, q, nu, nv, fn, params, out_buf, repeats) -> float:
    du = (fn.u_range[1] - fn.u_range[0]) / nu
    dv = (fn.v_range[1] - fn.v_range[0]) / nv
    best = None
    for r in range(repeats + 1):   # the first run is a warm-up
        evt = k(q, (nu, nv), None, np.uint32(0), np.float32(fn.u_range[0]), np.float32(du),
                np.float32(fn.v_range[0]), np.float32(dv), np.uint32(nu), params.data, out_buf.data)
        evt.wait()
        if r:
            t = (evt.profile.end - evt.profile.start) * 1e-9
            best = t if best is None else min(best, t)
    return nu * nv / best


def _time_split(k, q, nu, nv, fn, params, out_buf, repeats, run: int) -> float:
    """Samples/s of eval_split_throughput over an nu x nv grid in runs of ``run`` down its lines."""
    split = surface_split(fn)
    (u0, u1), (v0, v1) = fn.u_range, fn.v_range
    line = (u0, (u1 - u0) / nu, v0, (v1 - v0) / nv, nu, nv)
    if split is not None and split.axis == SPLIT_V:   # lines of constant v, runs along u
        line = (v0, (v1 - v0) / nv, u0, (u1 - u0) / nu, nv, nu)
    a0, da, b0, db, na, nb = line
    best = None
    for r in range(repeats + 1):   # the first run is a warm-up
        evt = k(q, (na, nb // run), None, np.uint32(0), np.float32(a0), np.float32(da), np.float32(b0),
                np.float32(db), np.uint32(na), np.uint32(run), params.data, out_buf.data)
        evt.wait()
        if r:
            t = (evt.profile.end - evt.profile.start) * 1e-9
            best = t if best is None else min(best, t)
    return na * (nb // run) * run / best


def builtin_set(orders=SH_ORDERS) -> dict:
    fns = dict(all_functions())
    fns.update({f"sh_glyph order {o}": make_sh_glyph(o) for o in orders})
    return {name: fns[name] for name in sorted(fns)}


def function_throughput(nu=2048, nv=1024, before: bool = False, names=None, repeats: int = 3,
                        orders=SH_ORDERS) -> list[dict]:
    """One row per built-in (and SH glyph order): ``samples_per_s`` (positions),
    ``surface_samples_per_s`` (position + partials + normal), ``flops_per_sample`` /
    ``surface_flops_per_sample``, ``gflops`` / ``surface_gflops``, and ``peak_fraction`` /
    ``surface_peak_fraction`` of the measured FP32 peak (``peak_flops``, also ``peak_info_flops``
    when the device is known). ``before=True``: also the ``*_before`` fields, the same for the
    generator without shared CSE."""
    q = cl_device().queue
    out_buf = cla.empty(q, nu * nv, np.float32)
    peak = measured_peak()
    peak_info = peak_from_info(device_info(q.device))
    rows = []
    for name, fn in builtin_set(orders).items():
        if names is not None and name not in names:
            continue
        params = cla.to_device(q, np.concatenate([fn.device_blocks(fn.param_block()), np.zeros(1, np.float32)]))
        row = {"function": name, "peak_flops": peak, "peak_info_flops": peak_info}
        for opt, tag in ((True, ""), (False, "_before")) if before else ((True, ""),):
            src = cl_dispatch_source([fn], optimize=opt)
            kp = programs.kernel("eval_throughput", ["common/eval.cl"], generated=src, describe=fn.name)
            ks = programs.kernel("eval_surface_throughput", ["common/eval.cl"], generated=src, describe=fn.name)
            sp_pos = _time(kp, q, nu, nv, fn, params, out_buf, repeats)
            sp_surf = _time(ks, q, nu, nv, fn, params, out_buf, repeats)
            if opt:   # the surface split in runs, as the point renderer on this device takes them
                kx = programs.kernel("eval_split_throughput", ["common/eval.cl"], generated=src, describe=fn.name)
                run = sample_run(cl_device().is_gpu)
                row.update({"split_axis": "none" if surface_split(fn) is None else "uv"[surface_split(fn).axis - 1],
                            "split_run": run,
                            "split_samples_per_s": _time_split(kx, q, nu, nv, fn, params, out_buf, repeats, run),
                            "split_samples_per_s_run16": _time_split(kx, q, nu, nv, fn, params, out_buf, repeats, 16)})
            if fn.is_snippet:
                fp = fs = None   # the user's own C: not counted
            else:
                f = function_flops(fn, opt)
                fp = f["position"] + SUM_FLOPS[0]
                fs = f["surface"] + NORMAL_FLOPS + SUM_FLOPS[1]
            row.update({f"samples_per_s{tag}": sp_pos, f"surface_samples_per_s{tag}": sp_surf,
                        f"flops_per_sample{tag}": fp, f"surface_flops_per_sample{tag}": fs})
            for k_sp, k_f, pre in ((sp_pos, fp, ""), (sp_surf, fs, "surface_")):
                fl = None if k_f is None else k_f * k_sp
                row[f"{pre}gflops{tag}"] = None if fl is None else fl / 1e9
                row[f"{pre}peak_fraction{tag}"] = None if fl is None else fl / peak
        rows.append(row)
    return rows


def format_function_throughput(rows: list[dict]) -> list[str]:
    """Markdown lines of the rows (for run.py's format_markdown)."""
    if not rows:
        return []
    peak = rows[0]["peak_flops"]
    info = rows[0].get("peak_info_flops")
    lines = ["", f"FP32 peak: {peak / 1e9:,.0f} GFLOP/s measured (fma_ceiling)"
             + (f", {info / 1e9:,.0f} GFLOP/s from the device info" if info else ""), "",
             "| function | positions/s | FLOP/sample | % peak | surface samples/s | FLOP/sample | % peak |",
             "|---|---:|---:|---:|---:|---:|---:|"]

    def f(x, fmt):
        return "n/a" if x is None else format(x, fmt)

    for r in rows:
        lines.append(f"| {r['function']} | {r['samples_per_s'] / 1e6:,.0f} M | {f(r['flops_per_sample'], 'd')} | "
                     f"{f(r['peak_fraction'] and 100 * r['peak_fraction'], '.1f')} | "
                     f"{r['surface_samples_per_s'] / 1e6:,.0f} M | {f(r['surface_flops_per_sample'], 'd')} | "
                     f"{f(r['surface_peak_fraction'] and 100 * r['surface_peak_fraction'], '.1f')} |")
    if "split_samples_per_s" in rows[0]:
        lines += ["", "The surface split (codegen_cl.split_surface): a work-item evaluates the steps of one "
                  "parameter once per grid line and the rest per sample down a run of that line "
                  f"(runs of {rows[0]['split_run']}, as the point renderer takes them on this device, and of 16):", "",
                  "| function | split along | surface samples/s | split, runs of " f"{rows[0]['split_run']}" " | × | runs of 16 | × |",
                  "|---|---|---:|---:|---:|---:|---:|"]
        for r in rows:
            base = r["surface_samples_per_s"]
            lines.append(f"| {r['function']} | {r['split_axis']} | {base / 1e6:,.0f} M | "
                         f"{r['split_samples_per_s'] / 1e6:,.0f} M | {r['split_samples_per_s'] / base:.2f} | "
                         f"{r['split_samples_per_s_run16'] / 1e6:,.0f} M | {r['split_samples_per_s_run16'] / base:.2f} |")
    if "samples_per_s_before" in rows[0]:
        lines += ["", "Before/after the shared CSE (samples/s, FLOP/sample):", "",
                  "| function | positions before | after | FLOP before | after | surface before | after | "
                  "FLOP before | after |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in rows:
            lines.append(f"| {r['function']} | {r['samples_per_s_before'] / 1e6:,.1f} M | {r['samples_per_s'] / 1e6:,.1f} M | "
                         f"{f(r['flops_per_sample_before'], 'd')} | {f(r['flops_per_sample'], 'd')} | "
                         f"{r['surface_samples_per_s_before'] / 1e6:,.1f} M | {r['surface_samples_per_s'] / 1e6:,.1f} M | "
                         f"{f(r['surface_flops_per_sample_before'], 'd')} | {f(r['surface_flops_per_sample'], 'd')} |")
    return lines
