//! Benchmarks of the spectroscopy stage (criterion): the Voigt function (fast against exact),
//! cross-sections (multigrid against direct), and table look-ups. `cargo bench --bench
//! spectroscopy`. The HAPI side-by-side comparison is `validation/hapi_benchmark/`.
use std::hint::black_box;
use std::path::PathBuf;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};

use lidarsim::atmosphere::StandardAtmosphere;
use lidarsim::spectroscopy::voigt::{re_w, re_w_exact};
use lidarsim::spectroscopy::xsec::GasState;
use lidarsim::spectroscopy::{
    GasOpticalDepthTable, LblOptions, LineFilter, LineList, LineShapeModel, VoigtMethod,
    WavenumberGrid, cross_section,
};

fn voigt(c: &mut Criterion) {
    // A line's grid points at 1 atm (y ≈ 10) and 0.01 atm (y ≈ 0.1), out to 25 cm⁻¹ (x ≈ 3500).
    let zs: Vec<(f64, f64)> = (0..1000)
        .flat_map(|i| {
            let x = 3500.0 * (i as f64 / 1000.0).powi(3);
            [(x, 10.5), (x, 0.1)]
        })
        .collect();
    let mut g = c.benchmark_group("voigt");
    g.throughput(Throughput::Elements(zs.len() as u64));
    g.bench_function("re_w_fast", |b| {
        b.iter(|| zs.iter().map(|&(x, y)| re_w(black_box(x), y)).sum::<f64>())
    });
    g.bench_function("re_w_exact", |b| {
        b.iter(|| {
            zs.iter()
                .map(|&(x, y)| re_w_exact(black_box(x), y))
                .sum::<f64>()
        })
    });
    g.finish();
}

fn xsec(c: &mut Criterion) {
    let state = GasState {
        pressure_pa: 101_325.0,
        temperature_k: 296.0,
        self_vmr: 0.0,
    };
    let band = LineList::co2_30012_band_model();
    let grid = WavenumberGrid::new(6355.0, 6365.0, 0.001).unwrap();
    let mut g = c.benchmark_group("cross_section");
    g.sample_size(10);
    g.throughput(Throughput::Elements(grid.len as u64));
    g.bench_function("band_model_10cm1_multigrid", |b| {
        b.iter(|| cross_section(&band, 2, &state, &grid, &LblOptions::default()).unwrap())
    });
    let direct = LblOptions {
        multigrid: false,
        ..Default::default()
    };
    g.bench_function("band_model_10cm1_direct_fast_voigt", |b| {
        b.iter(|| cross_section(&band, 2, &state, &grid, &direct).unwrap())
    });
    let exact = LblOptions {
        multigrid: false,
        voigt: VoigtMethod::Exact,
        ..Default::default()
    };
    g.bench_function("band_model_10cm1_direct_exact_voigt", |b| {
        b.iter(|| cross_section(&band, 2, &state, &grid, &exact).unwrap())
    });
    // The item-8 workload, when the shared HITRAN file is there.
    let shared = std::env::var_os("LIDARSIM_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared"));
    let par = shared.join("data/hitran/CO2_626_6000-6400_HITRAN2016.par");
    if par.is_file() {
        let lines = LineList::read_par(&par, &LineFilter::window(6300.0, 6400.0)).unwrap();
        let big = WavenumberGrid::new(6300.0, 6400.0, 0.001).unwrap();
        g.throughput(Throughput::Elements(big.len as u64));
        let opts = LblOptions {
            voigt: VoigtMethod::Fast,
            ..LblOptions::hapi_reference()
        };
        g.bench_function("hitran_2678_lines_100cm1_multigrid", |b| {
            b.iter(|| cross_section(&lines, 2, &state, &big, &opts).unwrap())
        });
    }
    g.finish();
}

/// Beyond Voigt (issue 15, item 7): the NIST list of the 30012 band (51 lines) on the grid of
/// the HAPI benchmark (6300–6400 cm⁻¹ every 0.001 cm⁻¹, 1 atm), with the Voigt, the
/// speed-dependent Voigt and Hartmann-Tran with line mixing, multigrid and direct; throughput
/// in line·points.
fn beyond_voigt(c: &mut Criterion) {
    let shared = std::env::var_os("LIDARSIM_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared"));
    let csv = shared.join("data/nist_30012/CO2_30012_NIST_SDNGP_LM.csv");
    if !csv.is_file() {
        println!("skipped: {} is absent", csv.display());
        return;
    }
    let lines = LineList::read(&csv, &LineFilter::default()).unwrap();
    let grid = WavenumberGrid::new(6300.0, 6400.0, 0.001).unwrap();
    let state = GasState {
        pressure_pa: 101_325.0,
        temperature_k: 296.0,
        self_vmr: 0.0004,
    };
    let mut g = c.benchmark_group("beyond_voigt");
    g.sample_size(10);
    g.throughput(Throughput::Elements(grid.len as u64 * lines.len() as u64));
    for (name, shape, mixing) in [
        ("voigt", LineShapeModel::Voigt, false),
        ("sdvoigt", LineShapeModel::SdVoigt, false),
        ("ht_line_mixing", LineShapeModel::HartmannTran, true),
    ] {
        let fast = LblOptions {
            line_shape: shape,
            line_mixing: mixing,
            ..Default::default()
        };
        g.bench_function(format!("{name}_multigrid"), |b| {
            b.iter(|| cross_section(&lines, 2, &state, &grid, &fast).unwrap())
        });
        let direct = LblOptions {
            multigrid: false,
            ..fast
        };
        g.bench_function(format!("{name}_direct"), |b| {
            b.iter(|| cross_section(&lines, 2, &state, &grid, &direct).unwrap())
        });
    }
    g.finish();
}

fn table(c: &mut Criterion) {
    let mut prof = StandardAtmosphere::UsStandard.profile();
    for g in prof.gases.iter_mut().filter(|g| g.name == "CO2") {
        g.vmr.iter_mut().for_each(|v| *v *= 420.0 / 330.0);
    }
    let lines = LineList::co2_30012_band_model();
    let edges: Vec<f64> = (0..=40).map(|i| i as f64 * 250.0).collect();
    let grid = WavenumberGrid::new(6359.0, 6361.0, 0.0005).unwrap();
    let mut g = c.benchmark_group("table");
    g.sample_size(10);
    g.bench_function("compute_40_layers_2cm1", |b| {
        b.iter(|| {
            GasOpticalDepthTable::compute(&prof, &lines, &edges, &grid, &LblOptions::default())
                .unwrap()
        })
    });
    let t = GasOpticalDepthTable::compute(&prof, &lines, &edges, &grid, &LblOptions::default())
        .unwrap();
    g.bench_function("layer_tau_one_channel_40_layers", |b| {
        b.iter(|| t.layer_tau(black_box(6359.96123)).unwrap())
    });
    g.finish();
}

criterion_group! {
    name = group;
    // No HTML plots: criterion's plotters backend needs system fonts this machine lacks.
    config = Criterion::default().without_plots();
    targets = voigt, xsec, beyond_voigt, table
}
criterion_main!(group);
