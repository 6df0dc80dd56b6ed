"""XCO2 bias from multiple scattering: the space IPDA and the airborne DIAL/IPDA against the
optical depth of an ice cloud between the lidar and the surface and the receiver's field of
view, with and without a low water cloud just above the target (issue 40, item 3).

For every case one `lidarsim run` with the Monte Carlo (all fields of view in one run) gives
retrieval.csv; the bias of the IPDA XCO2 from multiple scattering is all orders minus order 1
of the same photons (its error: the product's Monte Carlo standard error), next to the total
bias against the truth. One case per instrument (ice cloud τ = 1) is also run with
`jacobians = true`: its weighting.csv gives the single-scatter and the multiple-scattering-aware
weighting functions, drawn in weighting.png, and Σ_layers of their difference, which equals the
bias (`tests/multiple_scattering.rs` checks this in every product).

Usage: python run.py [LIDARSIM] [PHOTONS]   (defaults: target/release/lidarsim, 200000)
       python run.py --plot-only             (the figures from the CSV files)
Writes ms_bias.csv, ms_bias.png, weighting.csv (the two cases' IPDA rows) and weighting.png.
"""
import csv
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
ARGS = [a for a in sys.argv[1:] if not a.startswith("--")]
LIDARSIM = ARGS[0] if ARGS else str(ROOT / "target/release/lidarsim")
PHOTONS = int(ARGS[1]) if len(ARGS) > 1 else 200_000
TAUS = [0.0, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0]
FOVS = [0.1, 0.2, 0.5, 1.0, 2.0]
INSTRUMENTS = {
    # scene, ice cloud base and top [m] (the aircraft flies at 8 km)
    "space_ipda": ("spaceborne_co2_ipda.toml", 10_000.0, 11_000.0),
    "airborne_dial": ("airborne_co2_dial.toml", 5_000.0, 5_500.0),
}
LOW_CLOUD = (1_000.0, 1_300.0, 0.3)  # base, top [m], optical depth: water, just above the target


def layer(name, base, top, tau, g):
    ext_km = tau / ((top - base) / 1000.0)
    return (f'\n[[layer]]\nname = "{name}"\nbase_m = {base}\ntop_m = {top}\n'
            f"extinction_per_km = {ext_km}\nsingle_scattering_albedo = 1.0\n"
            f'phase = {{ kind = "henyey_greenstein", g = {g} }}\n')


def scene_text(instrument, tau, low, jacobians):
    name, base, top = INSTRUMENTS[instrument]
    text = (ROOT / "scenes" / name).read_text()
    fovs = ", ".join(str(f) for f in FOVS)
    text = text.replace("fov_full_angle_mrad = [0.2, 0.5]", f"fov_full_angle_mrad = [{fovs}]")
    text = text.replace("fov_full_angle_mrad = [0.2, 1.0]", f"fov_full_angle_mrad = [{fovs}]")
    extra = ""
    if tau > 0:
        extra += layer("ice cloud", base, top, tau, 0.85)
    if low:
        extra += layer("low water cloud", LOW_CLOUD[0], LOW_CLOUD[1], LOW_CLOUD[2], 0.85)
    text = text.replace("[surface]", extra + "\n[surface]")
    if jacobians:
        # Only the gates near the surface (the IPDA's target window; the Jacobians' memory
        # grows with layers × gates × fields of view × channels).
        text = text.replace("start_m = 440000.0", "start_m = 449000.0")
        text = text.replace("start_m = 1000.0", "start_m = 7000.0")
    # The run's settings: the Monte Carlo always (a thin cloud's multiple scattering is the
    # point of the study), orders to 5, and Jacobians where asked.
    keys = ("multiple_scattering", "max_order", "jacobians")
    lines = [l for l in text.splitlines() if not l.split("=")[0].strip() in keys]
    i = lines.index("[simulation]")
    lines[i + 1:i + 1] = ['multiple_scattering = "always"', "max_order = 5"] + (
        ["jacobians = true"] if jacobians else [])
    return "\n".join(lines) + "\n"


def run(instrument, tau, low, jacobians=False):
    with tempfile.TemporaryDirectory() as d:
        scene = ROOT / "scenes" / f"_ms_bias_{instrument}.toml"
        scene.write_text(scene_text(instrument, tau, low, jacobians))
        try:
            subprocess.run([LIDARSIM, "run", str(scene), "--photons", str(PHOTONS), "--out", d,
                            "--no-plots", "--no-netcdf"], check=True, capture_output=True)
        finally:
            scene.unlink()
        rows = list(csv.DictReader(open(Path(d) / "retrieval.csv")))
        weighting = list(csv.DictReader(open(Path(d) / "weighting.csv"))) if jacobians else []
    return rows, weighting


def ipda(rows, source, order, fov):
    for r in rows:
        if (r["method"], r["source"], r["order"]) == ("ipda", source, order) \
                and float(r["fov_full_angle_mrad"]) == fov:
            return r
    raise KeyError((source, order, fov))


def main():
    out = []
    for instrument in INSTRUMENTS:
        for low in (False, True):
            for tau in TAUS:
                rows, _ = run(instrument, tau, low)
                for fov in FOVS:
                    t = ipda(rows, "mc", "total", fov)
                    s = ipda(rows, "mc", "1st", fov)
                    out.append({
                        "instrument": instrument, "low_cloud": int(low), "ice_cloud_tau": tau,
                        "fov_full_angle_mrad": fov, "truth_ppm": t["truth_ppm"],
                        "bias_ppm": t["bias_ppm"],
                        "ms_bias_ppm": float(t["retrieved_ppm"]) - float(s["retrieved_ppm"]),
                        "ms_bias_stderr_ppm": t["mc_stderr_ppm"],
                        "single_scatter_bias_ppm": s["bias_ppm"],
                    })
                print(instrument, "low cloud" if low else "", tau, "done", flush=True)
    with open(HERE / "ms_bias.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(out[0]))
        w.writeheader()
        w.writerows(out)
    weights = []
    for instrument in INSTRUMENTS:
        _, wrows = run(instrument, 1.0, False, jacobians=True)
        weights += [dict(r, instrument=instrument) for r in wrows if r["method"] == "ipda"]
    with open(HERE / "weighting.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(weights[0]))
        w.writeheader()
        w.writerows(weights)
    plot(out, weights)


def plot(out, weights):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    # Colour-blind-safe, one colour per field of view everywhere.
    colours = plt.get_cmap("viridis")([0.0, 0.25, 0.5, 0.72, 0.9])
    fig, axes = plt.subplots(2, 2, figsize=(11, 8), sharex=True, constrained_layout=True)
    for i, instrument in enumerate(INSTRUMENTS):
        for j, low in enumerate((False, True)):
            ax = axes[j][i]
            ys = []
            for c, fov in zip(colours, FOVS):
                pts = [r for r in out if r["instrument"] == instrument and r["low_cloud"] == int(low)
                       and r["fov_full_angle_mrad"] == fov and r["ice_cloud_tau"] > 0]
                x = [r["ice_cloud_tau"] for r in pts]
                y = [float(r["ms_bias_ppm"]) for r in pts]
                e = [float(r["ms_bias_stderr_ppm"]) for r in pts]
                ys += y
                ax.errorbar(x, y, yerr=e, color=c, marker="o", ms=3, capsize=2,
                            label=f"{fov:g} mrad")
            ax.set_xscale("log")
            if min(ys) > 0:
                ax.set_yscale("log")
            else:
                ax.set_yscale("symlog", linthresh=min(abs(y) for y in ys if y != 0))
            ax.set_title(f"{instrument.replace('_', ' ')}: "
                         f"{'with a' if low else 'no'} low cloud above the target", fontsize=10)
            ax.set_ylabel("XCO2 bias from multiple scattering [ppm]")
            if j == 1:
                ax.set_xlabel("optical depth of the ice cloud")
    axes[0][1].legend(title="field of view", loc="upper left", bbox_to_anchor=(1.02, 1.0))
    fig.suptitle("IPDA XCO2 bias from multiple scattering (all orders − order 1, same photons; "
                 "error bars: 1 standard error)")
    fig.savefig(HERE / "ms_bias.png", dpi=130)

    fig, axes = plt.subplots(2, 2, figsize=(11, 9), constrained_layout=True)
    for col, instrument in enumerate(INSTRUMENTS):
        def profile(order, fov):
            pts = [r for r in weights if r["instrument"] == instrument and r["order"] == order
                   and float(r["fov_full_angle_mrad"]) == fov]
            by_layer = {int(r["layer"]): r for r in pts}
            return by_layer
        for c, fov in zip(colours, FOVS):
            one, total = profile("1st", fov), profile("total", fov)
            layers = sorted(set(one) | set(total))
            z = [0.5e-3 * (float((one.get(l) or total[l])["layer_bottom_m"])
                           + float((one.get(l) or total[l])["layer_top_m"])) for l in layers]
            dz = [1e-3 * (float((one.get(l) or total[l])["layer_top_m"])
                          - float((one.get(l) or total[l])["layer_bottom_m"])) for l in layers]
            w1 = [float(one[l]["derivative_ppm"]) if l in one else 0.0 for l in layers]
            wt = [float(total[l]["derivative_ppm"]) if l in total else 0.0 for l in layers]
            if fov in (FOVS[0], FOVS[-1]):
                axes[0][col].plot([w / d for w, d in zip(w1, dz)], z, ":", color=c,
                                  label=f"{fov:g} mrad, single scattering")
                axes[0][col].plot([w / d for w, d in zip(wt, dz)], z, "-", color=c, lw=0.8,
                                  label=f"{fov:g} mrad, all orders")
            diff = [(b - a) / d for a, b, d in zip(w1, wt, dz)]
            axes[1][col].plot(diff, z, color=c,
                              label=f"{fov:g} mrad: Σ = {sum(b - a for a, b in zip(w1, wt)):.2e} ppm")
        axes[0][col].set_title(f"{instrument.replace('_', ' ')}, ice cloud τ = 1", fontsize=10)
        axes[0][col].set_xlabel("∂XCO2/∂ln n(CO2) of the layer, per km [ppm/km]")
        axes[1][col].set_xlabel("all orders − single scattering [ppm/km]")
        axes[1][col].set_xscale("symlog", linthresh=1e-6)
        for row in (0, 1):
            axes[row][col].set_ylabel("altitude [km]")
        axes[1][col].legend(fontsize=7, loc="upper left", bbox_to_anchor=(0.0, -0.12), ncol=2)
    axes[0][1].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    fig.suptitle("IPDA weighting functions (above) and their change by multiple scattering "
                 "(below; Σ over the layers = the bias)")
    fig.savefig(HERE / "weighting.png", dpi=130)


if __name__ == "__main__":
    if "--plot-only" in sys.argv:
        read = lambda name: list(csv.DictReader(open(HERE / name)))
        rows = [dict(r, ice_cloud_tau=float(r["ice_cloud_tau"]), low_cloud=int(r["low_cloud"]),
                     fov_full_angle_mrad=float(r["fov_full_angle_mrad"])) for r in read("ms_bias.csv")]
        plot(rows, read("weighting.csv"))
    else:
        main()
