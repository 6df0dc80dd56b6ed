//! The command line's habits (issue 42, item 4), through the binary: counts in scientific
//! notation and with underscores, the scene as the first argument of every command, a scene
//! from standard input, `--set KEY=VALUE` overrides, relative-path errors that name what to use
//! instead.

use std::io::Write;
use std::path::Path;
use std::process::{Output, Stdio};

use crate::util::{lidarsim, lidarsim_command, lidarsim_ok, project_root, read_csv};

const DEFAULT: &str = lidarsim::scene::DEFAULT_SCENE_TOML;

/// Run lidarsim with `stdin` as its standard input, in `cwd`.
fn with_stdin(args: &[&str], stdin: &str, cwd: &Path) -> Output {
    let mut child = lidarsim_command()
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("lidarsim runs");
    child
        .stdin
        .take()
        .unwrap()
        .write_all(stdin.as_bytes())
        .unwrap();
    child.wait_with_output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A failed run: exit code 2 and one error line, which is returned.
fn refused(o: &Output) -> String {
    assert_eq!(o.status.code(), Some(2), "{}", stderr(o));
    let e = stderr(o);
    assert_eq!(e.lines().count(), 1, "{e}");
    assert!(e.starts_with("lidarsim: error: "), "{e}");
    e
}

/// 1-based line of the first line of `text` starting with `prefix`.
fn line_of(text: &str, prefix: &str) -> usize {
    text.lines().position(|l| l.starts_with(prefix)).unwrap() + 1
}

/// The photons a run traced, from its summary.json.
fn photons_of(dir: &Path) -> u64 {
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    fn find(v: &serde_json::Value) -> Option<u64> {
        match v {
            serde_json::Value::Object(m) => m
                .get("photons")
                .and_then(|p| p.as_u64())
                .or_else(|| m.values().find_map(find)),
            _ => None,
        }
    }
    find(&j).expect("photons in summary.json")
}

#[test]
fn counts_are_read_in_scientific_notation_and_with_underscores() {
    let dir = tempfile::tempdir().unwrap();
    for (text, n) in [("1e3", 1000), ("1_200", 1200), ("1.5e3", 1500)] {
        let out = dir.path().join(text);
        let stdout = lidarsim_ok([
            "run",
            "--photons",
            text,
            "--threads",
            "1",
            "--no-plots",
            "--no-netcdf",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(
            stdout.contains(&format!("transport: {n} photons")),
            "{text}: {stdout}"
        );
        assert_eq!(photons_of(&out), n);
    }
    for (text, why) in [
        ("1.5", "is not a whole number"),
        ("1e-3", "is not a whole number"),
        ("1e", "is not a count"),
        ("1__0", "is not a count"),
    ] {
        let e = refused(&lidarsim(["run", "--photons", text, "--out", "x"]));
        assert!(
            e.contains(&format!("--photons `{text}` {why}")),
            "{text}: {e}"
        );
    }
    // Another command's count, by the same parser.
    let e = refused(&lidarsim([
        "dial",
        "--ensemble",
        "2.5",
        "--out",
        dir.path().join("d").to_str().unwrap(),
    ]));
    assert!(e.contains("--ensemble `2.5` is not a whole number"), "{e}");
}

#[test]
fn a_count_in_the_scene_may_be_a_whole_float() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("s.toml");
    std::fs::write(
        &scene,
        DEFAULT.replacen("photons = 200000", "photons = 1.2e3", 1),
    )
    .unwrap();
    let out = dir.path().join("o");
    lidarsim_ok([
        "run",
        scene.to_str().unwrap(),
        "--threads",
        "1",
        "--no-plots",
        "--no-netcdf",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(photons_of(&out), 1200);
    let text = DEFAULT.replacen("photons = 200000", "photons = 1.5e3", 1);
    let text = text.replacen("seed = 1", "seed = 1e-3", 1);
    std::fs::write(&scene, &text).unwrap();
    let e = refused(&lidarsim(["run", scene.to_str().unwrap(), "--out", "x"]));
    let line = line_of(&text, "seed = ");
    assert!(
        e.contains(&format!(
            "s.toml:{line}: `seed`: 0.001 is not a whole number"
        )),
        "{e}"
    );
}

/// `select-lines` takes the scene as its first argument, as `run` and `dial` do; the former
/// `--scene FILE` still works (hidden) and gives the same table.
#[test]
fn select_lines_takes_the_scene_first() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("s.toml");
    // A different instrument than the default scene's, so that the scene matters.
    std::fs::write(
        &scene,
        DEFAULT.replacen(
            "telescope_diameter_m = 1.5",
            "telescope_diameter_m = 0.5",
            1,
        ),
    )
    .unwrap();
    let run = |scene_args: &[&str], out: &str| {
        let out = dir.path().join(out);
        let mut args = vec!["select-lines"];
        args.extend_from_slice(scene_args);
        args.extend_from_slice(&[
            "--atmosphere",
            "us_standard",
            "--on-cm1",
            "6360.040",
            "--off-cm1",
            "6360.610",
            "--co2-ppm",
            "420",
            "--layer-m",
            "1000",
            "--top-km",
            "60",
            "--no-plots",
            "--threads",
            "1",
            "--out",
            out.to_str().unwrap(),
        ]);
        lidarsim_ok(&args);
        std::fs::read_to_string(out.join("sensitivities.csv")).unwrap()
    };
    let s = scene.to_str().unwrap();
    let positional = run(&[s], "a");
    let option = run(&["--scene", s], "b");
    let default = run(&[], "c");
    assert_eq!(positional, option);
    assert_ne!(positional, default, "the scene was not read");
    let from_stdin = {
        let out = dir.path().join("d");
        let o = with_stdin(
            &[
                "select-lines",
                "-",
                "--atmosphere",
                "us_standard",
                "--on-cm1",
                "6360.040",
                "--off-cm1",
                "6360.610",
                "--co2-ppm",
                "420",
                "--layer-m",
                "1000",
                "--top-km",
                "60",
                "--no-plots",
                "--threads",
                "1",
                "--out",
                out.to_str().unwrap(),
            ],
            &std::fs::read_to_string(&scene).unwrap(),
            dir.path(),
        );
        assert!(o.status.success(), "{}", stderr(&o));
        std::fs::read_to_string(out.join("sensitivities.csv")).unwrap()
    };
    // The scene path is not in the table: the same numbers from a file and from stdin.
    assert_eq!(positional, from_stdin);
    let help = lidarsim_ok(["select-lines", "--help"]);
    assert!(help.contains("[SCENE]"), "{help}");
    assert!(!help.contains("--scene"), "{help}");
    // Both at once: clap's usage error (exit 2).
    let o = lidarsim([
        "select-lines",
        s,
        "--scene",
        s,
        "--atmosphere",
        "us_standard",
        "--off-cm1",
        "6360.61",
        "--co2-ppm",
        "420",
        "--out",
        "x",
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("cannot be used with"), "{}", stderr(&o));
}

#[test]
fn a_scene_is_read_from_standard_input() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("s.toml");
    std::fs::write(&file, DEFAULT).unwrap();
    let args = |out: &Path| {
        vec![
            "run".to_string(),
            "--photons".into(),
            "0".into(),
            "--no-plots".into(),
            "--no-netcdf".into(),
            "--out".into(),
            out.to_str().unwrap().to_string(),
        ]
    };
    let a = dir.path().join("a");
    let mut from_file = args(&a);
    from_file.insert(1, file.to_str().unwrap().into());
    lidarsim_ok(&from_file);
    let b = dir.path().join("b");
    let mut from_stdin = args(&b);
    from_stdin.insert(1, "-".into());
    let from_stdin: Vec<&str> = from_stdin.iter().map(String::as_str).collect();
    let o = with_stdin(&from_stdin, DEFAULT, dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        std::fs::read_to_string(a.join("returns.csv")).unwrap(),
        std::fs::read_to_string(b.join("returns.csv")).unwrap()
    );
    // An error names <stdin> and the line.
    let bad = DEFAULT.replacen("albedo = 0.2", "albedo = 2.0", 1);
    let o = with_stdin(&from_stdin, &bad, dir.path());
    let e = refused(&o);
    let line = line_of(&bad, "albedo = 2.0");
    assert!(
        e.contains(&format!("<stdin>:{line}: `surface.albedo`")),
        "{e}"
    );
    // Relative paths in a scene from stdin resolve against the current directory.
    let c1 = std::fs::read_to_string(project_root().join("scenes/bissonnette_c1.toml"))
        .unwrap()
        .replace("../phase_functions/", "phase_functions/");
    let out = dir.path().join("c1");
    let o = with_stdin(
        &[
            "run",
            "-",
            "--photons",
            "0",
            "--no-plots",
            "--out",
            out.to_str().unwrap(),
        ],
        &c1,
        &project_root(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let o = with_stdin(
        &["run", "-", "--photons", "0", "--out", "x"],
        &c1,
        dir.path(),
    );
    assert!(refused(&o).contains("<stdin>:"), "{}", stderr(&o));
    let help = lidarsim_ok(["run", "--help"]);
    assert!(help.contains("`-` reads it from standard input"), "{help}");
    assert!(help.contains("current directory"), "{help}");
}

/// `--set` changes the run as the same edit of the file does.
#[test]
fn set_overrides_a_scene_value_as_the_file_would() {
    let dir = tempfile::tempdir().unwrap();
    let edited = dir.path().join("edited.toml");
    std::fs::write(
        &edited,
        DEFAULT
            .replacen(
                "fov_full_angle_mrad = [0.2, 0.5]",
                "fov_full_angle_mrad = [1, 2]",
                1,
            )
            .replacen("wavenumber_cm1 = 6360.610", "wavenumber_cm1 = 6360.65", 1),
    )
    .unwrap();
    assert!(
        DEFAULT.contains("wavenumber_cm1 = 6360.610"),
        "update this test"
    );
    let run = |scene: Option<&Path>, sets: &[&str], out: &str| {
        let out = dir.path().join(out);
        let mut args: Vec<String> = vec!["run".into()];
        if let Some(s) = scene {
            args.push(s.to_str().unwrap().into());
        }
        for s in sets {
            args.push("--set".into());
            args.push(s.to_string());
        }
        args.extend(["--photons", "0", "--no-plots", "--no-netcdf", "--out"].map(String::from));
        args.push(out.to_str().unwrap().into());
        lidarsim_ok(&args);
        std::fs::read_to_string(out.join("returns.csv")).unwrap()
    };
    let by_file = run(Some(&edited), &[], "a");
    let by_set = run(
        None,
        &[
            "lidar.fov_full_angle_mrad=[1,2]",
            "channel.1.wavenumber_cm1=6360.65",
        ],
        "b",
    );
    assert_eq!(by_file, by_set);
    let (header, rows) = read_csv(&dir.path().join("b/returns.csv"));
    let fov = header
        .iter()
        .position(|h| h == "fov_full_angle_mrad")
        .unwrap();
    let fovs: std::collections::BTreeSet<&str> = rows.iter().map(|r| r[fov].as_str()).collect();
    assert_eq!(fovs.into_iter().collect::<Vec<_>>(), ["1", "2"]);
    // A count through --set, and a bare word as a string.
    let out = dir.path().join("c");
    lidarsim_ok([
        "run",
        "--set",
        "simulation.photons=1.1e3",
        "--set",
        "atmosphere.standard=tropical",
        "--set",
        "simulation.multiple_scattering=always",
        "--threads",
        "1",
        "--no-plots",
        "--no-netcdf",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(photons_of(&out), 1100);
}

#[test]
fn an_error_in_an_override_names_the_override() {
    let dir = tempfile::tempdir().unwrap();
    for (set, want) in [
        (
            "simulation.photons=1.5",
            "--set simulation.photons: 1.5 is not a whole number",
        ),
        (
            "lidar.fov_full_angle_mrad=[1,-2]",
            "--set lidar.fov_full_angle_mrad: -2 must lie in",
        ),
        ("lidar.bogus=1", "--set lidar.bogus: unknown field `bogus`"),
        (
            "channel.2.wavenumber_cm1=6360",
            "--set channel.2.wavenumber_cm1: `channel` has 2 tables (indices 0 to 1)",
        ),
        ("atmosphere.standard=mars", "--set atmosphere.standard: "),
        ("nokey", "KEY=VALUE"),
    ] {
        let e = refused(&lidarsim([
            "run",
            "--set",
            set,
            "--photons",
            "0",
            "--out",
            dir.path().join("x").to_str().unwrap(),
        ]));
        assert!(e.contains(want), "{set}: {e}");
    }
    assert!(!dir.path().join("x").exists());
    // A problem elsewhere in the file keeps the file's line, though the override added lines
    // before it.
    let scene = dir.path().join("bad.toml");
    let text = DEFAULT.replacen("albedo = 0.2", "albedo = 2.0", 1);
    std::fs::write(&scene, &text).unwrap();
    let e = refused(&lidarsim([
        "run",
        scene.to_str().unwrap(),
        "--set",
        "lidar.azimuth_deg=10",
        "--set",
        "lidar.polarisation=\"none\"",
        "--out",
        "x",
    ]));
    let line = line_of(&text, "albedo = 2.0");
    assert!(
        e.contains(&format!("bad.toml:{line}: `surface.albedo`")),
        "{e}"
    );
    // `dial` and `select-lines` take --set as well.
    let e = refused(&lidarsim([
        "dial",
        "--set",
        "retrieval.bogus=1",
        "--ensemble",
        "2",
        "--out",
        dir.path().join("d").to_str().unwrap(),
    ]));
    assert!(e.contains("--set retrieval.bogus: unknown field"), "{e}");
    let e = refused(&lidarsim([
        "select-lines",
        "--set",
        "lidar.telescope_diameter_m=-1",
        "--atmosphere",
        "us_standard",
        "--off-cm1",
        "6360.61",
        "--co2-ppm",
        "420",
        "--out",
        dir.path().join("s").to_str().unwrap(),
    ]));
    assert!(e.contains("--set lidar.telescope_diameter_m: "), "{e}");
}

/// A shipped scene copied out of `scenes/` loses its `../phase_functions/…` table: the error
/// names the built-in table to use instead, and that suggestion runs.
#[test]
fn a_copied_scene_is_told_the_built_in_table() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(project_root().join("scenes/bissonnette_c1.toml")).unwrap();
    let scene = dir.path().join("c1.toml");
    std::fs::write(&scene, &text).unwrap();
    let e = refused(&lidarsim([
        "run",
        scene.to_str().unwrap(),
        "--photons",
        "0",
        "--out",
        "x",
    ]));
    let line = line_of(&text, "phase = ");
    assert!(e.contains(&format!("c1.toml:{line}: `layer.phase`")), "{e}");
    let suggested = "phase = { kind = \"table\", builtin = \"bissonnette_c1_1064nm\" }";
    assert!(e.contains(suggested), "{e}");
    assert!(e.contains("relative to the scene's directory"), "{e}");
    let fixed = text
        .lines()
        .map(|l| {
            if l.starts_with("phase = ") {
                suggested
            } else {
                l
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(&scene, fixed).unwrap();
    let out = dir.path().join("o");
    lidarsim_ok([
        "run",
        scene.to_str().unwrap(),
        "--photons",
        "0",
        "--no-plots",
        "--out",
        out.to_str().unwrap(),
    ]);
    // And the built-in table is the shipped file: the same returns as the scene in place.
    let shipped = dir.path().join("p");
    lidarsim_ok([
        "run",
        project_root()
            .join("scenes/bissonnette_c1.toml")
            .to_str()
            .unwrap(),
        "--photons",
        "0",
        "--no-plots",
        "--out",
        shipped.to_str().unwrap(),
    ]);
    assert_eq!(
        std::fs::read_to_string(out.join("returns.csv")).unwrap(),
        std::fs::read_to_string(shipped.join("returns.csv")).unwrap()
    );
}

/// The cross-sections of `lbl` with `extra` arguments (the data rows only).
fn lbl_rows(dir: &Path, name: &str, extra: &[&str]) -> Result<String, String> {
    let out = dir.join(name);
    let mut args = vec![
        "lbl",
        "--pressure-atm",
        "1",
        "--temperature-k",
        "296",
        "--step-cm1",
        "0.01",
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let o = lidarsim(&args);
    if !o.status.success() {
        return Err(stderr(&o));
    }
    let text = std::fs::read_to_string(&out).unwrap();
    Ok(text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .collect::<Vec<_>>()
        .join("\n"))
}

#[test]
fn lbl_takes_its_range_in_wavenumbers_nm_or_um() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // 1571–1573 nm is 1e7/1573 … 1e7/1571 cm⁻¹.
    let lo = format!("{}", 1e7 / 1573.0);
    let hi = format!("{}", 1e7 / 1571.0);
    let cm1 = lbl_rows(d, "a.csv", &["--start-cm1", &lo, "--end-cm1", &hi]).unwrap();
    let nm = lbl_rows(d, "b.csv", &["--start-nm", "1571", "--end-nm", "1573"]).unwrap();
    let um = lbl_rows(d, "c.csv", &["--start-um", "1.573", "--end-um", "1.571"]).unwrap();
    assert!(cm1.lines().count() > 100, "{cm1}");
    assert_eq!(cm1, nm);
    assert_eq!(cm1, um);
    for (args, want) in [
        (
            &["--start-nm", "1571", "--end-cm1", "6400"][..],
            "in one unit",
        ),
        (&["--start-nm", "1571"][..], "--start-nm needs --end-nm"),
        (&[][..], "give the spectral range"),
    ] {
        let e = lbl_rows(d, "x.csv", args).unwrap_err();
        assert!(e.contains(want), "{args:?}: {e}");
    }
    // Wavelengths typed as wavenumbers: the message says what was probably meant.
    let e = lbl_rows(d, "x.csv", &["--start-cm1", "1570", "--end-cm1", "1580"]).unwrap_err();
    assert!(e.contains("no lines of"), "{e}");
    assert!(
        e.contains("did you mean --start-nm 1570 --end-nm 1580 (6329.1–6369.4 cm⁻¹)?"),
        "{e}"
    );
    let e = lbl_rows(d, "x.csv", &["--start-cm1", "1.57", "--end-cm1", "1.58"]).unwrap_err();
    assert!(
        e.contains("did you mean --start-um 1.57 --end-um 1.58"),
        "{e}"
    );
    // Nothing to suggest where no reading reaches a line.
    let e = lbl_rows(d, "x.csv", &["--start-cm1", "3000", "--end-cm1", "3001"]).unwrap_err();
    assert!(
        e.contains("no lines of") && !e.contains("did you mean"),
        "{e}"
    );
}

/// Several `--lines` files: the lines merged give what one file holding them all gives.
#[test]
fn lbl_merges_several_line_files() {
    let Some(hitran) = crate::util::shared_file("data/hitran/CO2_626_6000-6400_HITRAN2016.par")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let low = crate::util::par_records_in(&hitran, 6320.0, 6360.0);
    let high = crate::util::par_records_in(&hitran, 6360.0, 6400.0);
    let (a, b, all) = (d.join("a.par"), d.join("b.par"), d.join("all.par"));
    std::fs::write(&a, &low).unwrap();
    std::fs::write(&b, &high).unwrap();
    std::fs::write(&all, format!("{low}{high}")).unwrap();
    let range = ["--start-cm1", "6355", "--end-cm1", "6365"];
    let one = lbl_rows(
        d,
        "one.csv",
        &[&["--lines", all.to_str().unwrap()][..], &range].concat(),
    )
    .unwrap();
    let two = lbl_rows(
        d,
        "two.csv",
        &[
            &[
                "--lines",
                b.to_str().unwrap(),
                "--lines",
                a.to_str().unwrap(),
            ][..],
            &range,
        ]
        .concat(),
    )
    .unwrap();
    assert_eq!(one, two);
    let only_a = lbl_rows(
        d,
        "a.csv",
        &[&["--lines", a.to_str().unwrap()][..], &range].concat(),
    )
    .unwrap();
    assert_ne!(one, only_a, "the second file was not read");
    // A bad file is named.
    let bad = d.join("bad.par");
    std::fs::write(&bad, "not a line record\n").unwrap();
    let e = lbl_rows(
        d,
        "x.csv",
        &[
            &[
                "--lines",
                a.to_str().unwrap(),
                "--lines",
                bad.to_str().unwrap(),
            ][..],
            &range,
        ]
        .concat(),
    )
    .unwrap_err();
    assert!(e.contains(&format!("--lines {}", bad.display())), "{e}");
}

/// Off a terminal (stderr a pipe, as from `subprocess` or a batch job) the progress of long
/// work is written as log lines; `--quiet` silences them. `LIDARSIM_PROGRESS_AFTER_S=0` logs
/// from the start, so that a short run shows the lines.
#[test]
fn progress_is_logged_to_stderr_off_a_terminal() {
    let dir = tempfile::tempdir().unwrap();
    let run = |extra: &[&str], env: bool| {
        let mut c = lidarsim_command();
        c.args([
            "run",
            "--photons",
            "2e4",
            "--threads",
            "1",
            "--no-plots",
            "--no-netcdf",
        ])
        .args(extra)
        .arg("--out")
        .arg(dir.path().join("o"));
        if env {
            c.env("LIDARSIM_PROGRESS_AFTER_S", "0");
        } else {
            c.env_remove("LIDARSIM_PROGRESS_AFTER_S");
        }
        let o = c.output().unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        stderr(&o)
    };
    let log = run(&[], true);
    let lines: Vec<&str> = log.lines().collect();
    assert!(lines.len() >= 3, "{log}");
    let (last, progress) = lines.split_last().unwrap();
    assert!(last.starts_with("run: done, 100 batches in "), "{log}");
    let mut previous = -1.0;
    for l in progress {
        // run: 45 % (45/100 batches), 12 s elapsed, ~15 s left
        let rest = l.strip_prefix("run: ").expect(l);
        let (percent, rest) = rest.split_once(" % (").expect(l);
        let percent: f64 = percent.parse().unwrap();
        let (done, rest) = rest.split_once("/100 batches), ").expect(l);
        assert_eq!(done.parse::<f64>().unwrap(), percent, "{l}");
        assert!(percent > previous && percent < 100.0, "{log}");
        assert!(rest.contains(" elapsed"), "{l}");
        previous = percent;
    }
    assert_eq!(run(&["--quiet"], true), "");
    // A short run says nothing by default.
    assert_eq!(run(&[], false), "");
    // The studies report through the same facility.
    let o = lidarsim_command()
        .args([
            "select-lines",
            "--atmosphere",
            "tropical,us_standard,subarctic_winter",
            "--on-cm1",
            "6360.040",
            "--off-cm1",
            "6360.610",
            "--co2-ppm",
            "420",
            "--layer-m",
            "1000",
            "--no-plots",
            "--threads",
            "1",
            "--out",
        ])
        .arg(dir.path().join("s"))
        .env("LIDARSIM_PROGRESS_AFTER_S", "0")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let log = stderr(&o);
    assert!(log.contains("select-lines: 33 % (1/3 profiles)"), "{log}");
    assert!(log.contains("select-lines: done, 3 profiles in "), "{log}");
    // And lbl's layer mode, layer by layer.
    let o = lidarsim_command()
        .args([
            "lbl",
            "--atmosphere",
            "us_standard",
            "--sensor-altitude-m",
            "45000",
            "--zenith-deg",
            "180",
            "--layer-m",
            "1000",
            "--start-cm1",
            "6359",
            "--end-cm1",
            "6361",
            "--step-cm1",
            "0.01",
            "--out",
        ])
        .arg(dir.path().join("tau.csv"))
        .env("LIDARSIM_PROGRESS_AFTER_S", "0")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let log = stderr(&o);
    assert!(log.contains("lbl: 2 % (1/45 layers)"), "{log}");
    assert!(log.contains("lbl: done, 45 layers in "), "{log}");
}

/// Shards of a run with `--set` merge into the run itself: the shards store the edited text,
/// and the scene read again from it is the one they ran.
#[test]
fn shards_of_a_run_with_overrides_merge() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sets = [
        "--set",
        "simulation.photons=2e3",
        "--set",
        "lidar.fov_full_angle_mrad=[1,2]",
    ];
    for i in 0..2 {
        let shard = format!("{i}/2");
        lidarsim_ok(
            [
                &["run"][..],
                &sets,
                &["--threads", "1", "--shard", &shard, "--out"],
                &[d.join("s").to_str().unwrap()],
            ]
            .concat(),
        );
    }
    lidarsim_ok([
        "merge",
        d.join("s").to_str().unwrap(),
        "--no-plots",
        "--out",
        d.join("m").to_str().unwrap(),
    ]);
    lidarsim_ok(
        [
            &["run"][..],
            &sets,
            &["--threads", "1", "--no-plots", "--out"],
            &[d.join("r").to_str().unwrap()],
        ]
        .concat(),
    );
    assert_eq!(
        std::fs::read_to_string(d.join("m/returns.csv")).unwrap(),
        std::fs::read_to_string(d.join("r/returns.csv")).unwrap()
    );
}
