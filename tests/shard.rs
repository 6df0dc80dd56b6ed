//! Sharded runs: `run --shard I/N` and `merge` give the single run's files
//! byte for byte, and a merge refuses every shard set that is not one whole run, naming the
//! files.

use std::fs;
use std::path::{Path, PathBuf};

use lidarsim::shard::{self, ShardFile, ShardSpec};

use crate::util::path_arg as s;
use crate::util::{
    file_names, lidarsim, lidarsim_ok, project_root, shard_header, with_checksum, with_shard_header,
};

fn c1_scene() -> String {
    project_root()
        .join("scenes/bissonnette_c1.toml")
        .to_string_lossy()
        .into_owned()
}

/// `lidarsim run SCENE --shard I/N --out DIR` with extra arguments (`None`: the default scene).
fn shard(scene: Option<&str>, spec: &str, out: &Path, extra: &[&str]) {
    let mut args = vec!["run".to_string()];
    args.extend(scene.map(String::from));
    args.extend(["--shard", spec, "--out", &s(out), "--no-plots"].map(String::from));
    args.extend(extra.iter().map(|a| a.to_string()));
    lidarsim_ok(&args);
}

/// Every file of `single` equals its namesake in `merged` byte for byte, but summary.json,
/// which equals it once wall time, thread count and the scene's path (absolute in a merge) are
/// left out. Returns the names compared.
fn assert_same_outputs(single: &Path, merged: &Path) -> Vec<String> {
    let names = file_names(single);
    assert_eq!(names, file_names(merged), "the same files");
    for name in &names {
        let (a, b) = (
            fs::read(single.join(name)).unwrap(),
            fs::read(merged.join(name)).unwrap(),
        );
        if name == "summary.json" {
            let strip = |bytes: &[u8]| {
                let mut v: serde_json::Value = serde_json::from_slice(bytes).unwrap();
                let o = v.as_object_mut().unwrap();
                for k in ["wall_s", "threads", "scene"] {
                    assert!(o.remove(k).is_some(), "summary.json has {k}");
                }
                v
            };
            assert_eq!(strip(&a), strip(&b), "summary.json");
        } else if name == lidarsim::netcdf::RUN_FILE {
            // Its `history` holds the time and the command line; the numbers are the CSV's
            // (tests/netcdf.rs).
            assert!(!b.is_empty(), "{name} written by the merge");
        } else {
            assert!(a == b, "{name} differs between the run and the merge");
        }
    }
    names
}

/// The test: one run, and the merge of 4 shards (computed on 1 and 2 threads, in two
/// directories, one given as a file), give byte-identical returns.csv, signals.csv,
/// retrieval.csv and figures. The default scene has a laser (line combinations with their
/// covariances), a receiver and a retrieval; the C.1 scene a cloud and a phase table file.
#[test]
fn one_run_and_the_merge_of_four_shards_give_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (name, scene) in [("default", None), ("c1", Some(c1_scene()))] {
        let single = d.join(format!("{name}_single"));
        let mut args = vec!["run".to_string()];
        args.extend(scene.clone());
        args.extend(
            [
                "--photons",
                "2000",
                "--seed",
                "7",
                "--threads",
                "2",
                "--out",
                &s(&single),
            ]
            .map(String::from),
        );
        lidarsim_ok(&args);
        let (a, b) = (d.join(format!("{name}_a")), d.join(format!("{name}_b")));
        for (spec, out, threads) in [
            ("0/4", &a, "1"),
            ("1/4", &a, "2"),
            ("2/4", &b, "1"),
            ("3/4", &b, "2"),
        ] {
            shard(
                scene.as_deref(),
                spec,
                out,
                &["--photons", "2000", "--seed", "7", "--threads", threads],
            );
        }
        let merged = d.join(format!("{name}_merged"));
        let stdout = lidarsim_ok([
            "merge".to_string(),
            s(&a),
            s(&b.join("shard-2-of-4.lshard")),
            s(&b.join("shard-3-of-4.lshard")),
            "--out".into(),
            s(&merged),
        ]);
        assert!(stdout.contains("merged 4 shards"), "{stdout}");
        let names = assert_same_outputs(&single, &merged);
        assert!(names.contains(&"returns.csv".to_string()), "{names:?}");
        if scene.is_none() {
            for f in ["signals.csv", "retrieval.csv", "returns.png"] {
                assert!(names.contains(&f.to_string()), "{f} in {names:?}");
            }
        }
    }
}

/// A shard's batches are the same bytes whatever the thread count; only the trailer (wall
/// time, threads, checksum) differs.
#[test]
fn a_shard_is_the_same_on_any_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let (one, two) = (dir.path().join("one"), dir.path().join("two"));
    let scene = c1_scene();
    shard(
        Some(&scene),
        "1/3",
        &one,
        &["--photons", "3000", "--threads", "1"],
    );
    shard(
        Some(&scene),
        "1/3",
        &two,
        &["--photons", "3000", "--threads", "2"],
    );
    let name = "shard-1-of-3.lshard";
    let (a, b) = (
        ShardFile::read(&one.join(name)).unwrap(),
        ShardFile::read(&two.join(name)).unwrap(),
    );
    assert_eq!(a.header, b.header);
    assert_eq!((a.threads, b.threads), (1, 2));
    let (ta, tb): (Vec<_>, Vec<_>) = (a.batches().collect(), b.batches().collect());
    assert_eq!(ta.len(), 33, "batches 34..67 of 100");
    assert_eq!(ta[0].index, 34);
    assert!(ta == tb);
    let (ba, bb) = (
        fs::read(one.join(name)).unwrap(),
        fs::read(two.join(name)).unwrap(),
    );
    assert_eq!(ba.len(), bb.len());
    assert_eq!(ba[..ba.len() - 24], bb[..bb.len() - 24]);
}

/// `lidarsim merge ARGS --out DIR`: exit code 2, one line on stderr, nothing written.
fn merge_refused(args: &[PathBuf]) -> String {
    let out_dir = tempfile::tempdir().unwrap();
    let out = out_dir.path().join("merged");
    let mut a = vec!["merge".to_string()];
    a.extend(args.iter().map(|p| s(p)));
    a.extend(["--out".to_string(), s(&out)]);
    let o = lidarsim(&a);
    let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!out.exists(), "nothing written");
    stderr
}

/// Four shards of C.1 at 400 photons, seed 1, in `dir`.
fn four_shards(dir: &Path, extra: &[&str]) -> Vec<PathBuf> {
    let scene = c1_scene();
    let mut args = vec!["--threads", "1"];
    if !extra.contains(&"--photons") {
        args.extend(["--photons", "400"]);
    }
    args.extend_from_slice(extra);
    (0..4)
        .map(|i| {
            shard(Some(&scene), &format!("{i}/4"), dir, &args);
            dir.join(format!("shard-{i}-of-4.lshard"))
        })
        .collect()
}

#[test]
fn merge_refuses_a_missing_or_duplicated_shard_naming_the_files() {
    let dir = tempfile::tempdir().unwrap();
    let files = four_shards(&dir.path().join("a"), &[]);
    let e = merge_refused(&[files[0].clone(), files[1].clone(), files[3].clone()]);
    assert!(e.contains("1 of 4 shards missing (2)"), "{e}");
    assert!(e.contains("shard-3-of-4.lshard"), "{e}");
    // The same shard in a second directory.
    let other = dir.path().join("b");
    fs::create_dir(&other).unwrap();
    fs::copy(&files[2], other.join("copy.lshard")).unwrap();
    let e = merge_refused(&[dir.path().join("a"), other.clone()]);
    assert!(
        e.contains("shard 2/4 is given twice")
            && e.contains("copy.lshard")
            && e.contains("shard-2-of-4.lshard"),
        "{e}"
    );
    let empty = dir.path().join("empty");
    fs::create_dir(&empty).unwrap();
    let e = merge_refused(std::slice::from_ref(&empty));
    assert!(e.contains("no shard files") && e.contains("empty"), "{e}");
    let e = merge_refused(&[dir.path().join("nowhere")]);
    assert!(e.contains("nowhere"), "{e}");
}

#[test]
fn merge_refuses_shards_of_different_seeds_photons_scenes_or_options() {
    let dir = tempfile::tempdir().unwrap();
    let base = four_shards(&dir.path().join("base"), &[]);
    let seed = four_shards(&dir.path().join("seed"), &["--seed", "2"]);
    let photons = four_shards(&dir.path().join("photons"), &["--photons", "800"]);
    let ddis = four_shards(&dir.path().join("ddis"), &["--ddis-epsilon", "0.2"]);
    let cases = [
        (&seed, "the seed differs (1 against 2)"),
        (&photons, "the photon count differs (400 against 800)"),
        (&ddis, "the DDIS probability differs (0.3 against 0.2)"),
    ];
    for (other, why) in cases {
        let e = merge_refused(&[
            base[0].clone(),
            base[1].clone(),
            base[2].clone(),
            other[3].clone(),
        ]);
        assert!(e.contains(why), "{why}: {e}");
        assert!(e.contains(&s(&base[0])) && e.contains(&s(&other[3])), "{e}");
    }
    // The same scene with another extinction: same seed and photons, another digest.
    let text = fs::read_to_string(c1_scene())
        .unwrap()
        .replace("extinction_per_km = 17.23", "extinction_per_km = 17.24")
        .replace(
            "../phase_functions/",
            &format!("{}/", s(&project_root().join("phase_functions"))),
        );
    let other_scene = dir.path().join("other.toml");
    fs::write(&other_scene, text).unwrap();
    let out = dir.path().join("other");
    shard(
        Some(&s(&other_scene)),
        "3/4",
        &out,
        &["--photons", "400", "--threads", "1"],
    );
    let e = merge_refused(&[
        base[0].clone(),
        base[1].clone(),
        base[2].clone(),
        out.join("shard-3-of-4.lshard"),
    ]);
    assert!(
        e.contains("the scene (digest) differs") && e.contains("other.toml"),
        "{e}"
    );
    // Shard counts.
    let three = dir.path().join("three");
    shard(Some(&c1_scene()), "2/3", &three, &["--photons", "400"]);
    let e = merge_refused(&[base[0].clone(), three.join("shard-2-of-3.lshard")]);
    assert!(e.contains("the shard count differs (4 against 3)"), "{e}");
}

/// The scene a merge reads again must be the one the shards ran, down to the files it reads:
/// a phase table changed between the shards and the merge is refused.
#[test]
fn merge_refuses_a_scene_whose_files_changed_since_the_shards() {
    let dir = tempfile::tempdir().unwrap();
    let table = dir.path().join("c1.txt");
    fs::copy(
        project_root().join("phase_functions/bissonnette_c1_1064nm.txt"),
        &table,
    )
    .unwrap();
    let text = fs::read_to_string(c1_scene())
        .unwrap()
        .replace("../phase_functions/bissonnette_c1_1064nm.txt", "c1.txt");
    let scene = dir.path().join("c1.toml");
    fs::write(&scene, text).unwrap();
    let out = dir.path().join("shards");
    for i in 0..2 {
        shard(
            Some(&s(&scene)),
            &format!("{i}/2"),
            &out,
            &["--photons", "400"],
        );
    }
    let merged = dir.path().join("merged");
    lidarsim_ok(["merge".to_string(), s(&out), "--out".into(), s(&merged)]);
    let t = fs::read_to_string(&table).unwrap();
    assert!(t.contains("0.0100,7.59310094e+02"));
    fs::write(
        &table,
        t.replace("0.0100,7.59310094e+02", "0.0100,7.59310095e+02"),
    )
    .unwrap();
    let e = merge_refused(&[out]);
    assert!(
        e.contains("is not the one the shards ran") && e.contains("c1.toml"),
        "{e}"
    );
}

/// `bytes` with its header replaced by `edit(header)` and a correct checksum.
fn with_header(bytes: &[u8], edit: impl Fn(&mut serde_json::Value)) -> Vec<u8> {
    let (mut h, _) = shard_header(bytes).expect("a shard with a readable header");
    edit(&mut h);
    with_shard_header(bytes, &h)
}

/// A corrupt, truncated, foreign, future-format or other-version shard: one line naming the
/// file and what is wrong.
#[test]
fn merge_refuses_damaged_and_foreign_shard_files() {
    let dir = tempfile::tempdir().unwrap();
    let files = four_shards(&dir.path().join("a"), &[]);
    let good = fs::read(&files[1]).unwrap();
    let bad = dir.path().join("bad");
    fs::create_dir(&bad).unwrap();
    let mut flipped = good.clone();
    flipped[good.len() / 2] ^= 0x10;
    let mut future = good.clone();
    // A format this lidarsim does not know: the next one.
    future[16..20].copy_from_slice(&(lidarsim::shard::FORMAT + 1).to_le_bytes());
    let future_message = format!("shard file format {}", lidarsim::shard::FORMAT + 1);
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("truncated", good[..good.len() - 100].to_vec(), "truncated"),
        ("flipped", flipped, "corrupt: checksum"),
        (
            "text",
            b"returns,csv\n1,2\n".to_vec(),
            "not a lidarsim shard file",
        ),
        ("empty", Vec::new(), "not a lidarsim shard file"),
        ("future", future, future_message.as_str()),
        (
            "version",
            with_header(&good, |h| h["lidarsim_version"] = "0.0.1".into()),
            "written by lidarsim 0.0.1",
        ),
        (
            "range",
            with_header(&good, |h| {
                h["first_batch"] = 0.into();
                h["end_batch"] = 25.into();
            }),
            "inconsistent header",
        ),
        (
            "sizes",
            with_header(&good, |h| h["bins_per_batch"] = 7.into()),
            "where its header announces",
        ),
        (
            "tail",
            [good.as_slice(), &[0u8; 8]].concat(),
            "bytes beyond the end",
        ),
    ];
    for (name, bytes, why) in cases {
        let p = bad.join(format!("{name}.lshard"));
        fs::write(&p, bytes).unwrap();
        let e = merge_refused(&[
            files[0].clone(),
            p.clone(),
            files[2].clone(),
            files[3].clone(),
        ]);
        assert!(e.contains(why) && e.contains(&s(&p)), "{name}: {e}");
        fs::remove_file(&p).unwrap();
    }
}

/// No truncation or byte flip of a shard file makes the reader panic; each is refused (a flip
/// in the trailer's wall time or thread count aside: the checksum covers them too).
#[test]
fn every_truncation_and_flip_of_a_shard_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let scene = c1_scene();
    shard(Some(&scene), "0/50", dir.path(), &["--photons", "200"]);
    let path = dir.path().join("shard-00-of-50.lshard");
    let good = fs::read(&path).unwrap();
    assert!(ShardFile::parse(&path, good.clone()).is_ok());
    for len in (0..good.len())
        .step_by(97)
        .chain(good.len() - 30..good.len())
    {
        assert!(
            ShardFile::parse(&path, good[..len].to_vec()).is_err(),
            "length {len}"
        );
    }
    for at in (0..good.len())
        .step_by(89)
        .chain(good.len() - 30..good.len())
    {
        let mut b = good.clone();
        b[at] ^= 0x04;
        let e = ShardFile::parse(&path, b).expect_err("flipped byte");
        assert!(e.to_string().contains(&s(&path)), "{e}");
    }
}

#[test]
fn shard_options_are_checked_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let out = s(&dir.path().join("out"));
    let scene = c1_scene();
    for (spec, why) in [
        ("4/4", "shard 4 of 4 does not exist"),
        ("0/0", "number of shards must lie in"),
        ("x", "is not I/N"),
        ("1/2/3", "is not I/N"),
        ("0/101", "101 shards of a run of 100 batches"),
    ] {
        let o = lidarsim([
            "run",
            &scene,
            "--photons",
            "400",
            "--shard",
            spec,
            "--out",
            &out,
        ]);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{spec}: {e}");
        assert!(e.contains(why), "{spec}: {e}");
    }
    let o = lidarsim([
        "run",
        &scene,
        "--photons",
        "0",
        "--shard",
        "0/2",
        "--out",
        &out,
    ]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        o.status.code() == Some(2) && e.contains("a shard needs photons"),
        "{e}"
    );
    assert!(!dir.path().join("out").exists());
}

/// The library's own path: shards written by [`shard::run`] merge by [`shard::merge`] into the
/// Monte Carlo of [`lidarsim::pipeline::run`], equal as numbers.
#[test]
fn library_shards_fold_into_the_pipelines_result() {
    let mut scene = shard::read_scene(Some(Path::new(&c1_scene()))).unwrap();
    scene
        .override_simulation(Some(1000), None, Some(1))
        .unwrap();
    let whole = lidarsim::pipeline::run(&scene).unwrap();
    let dir = tempfile::tempdir().unwrap();
    for i in 0..3 {
        let r = shard::run(&scene, ShardSpec { index: i, count: 3 }, dir.path()).unwrap();
        assert_eq!(r.total_batches, 100);
    }
    let merged = shard::merge(&[dir.path().to_path_buf()]).unwrap();
    let (a, b) = (whole.mc.unwrap(), merged.run.mc.unwrap());
    assert_eq!(a.returns, b.returns);
    assert_eq!(a.stats, b.stats);
    assert_eq!(a.photons, b.photons);
    assert_eq!(merged.shards, 3);
}

/// A run watched for a stop (the Python package's path, `Prepared::trace_until`) is the
/// pipeline's run while the flag stays down, and ends with `Stopped` once it is up.
#[test]
fn a_watched_run_is_the_run_until_it_is_stopped() {
    use std::sync::atomic::AtomicBool;
    let mut scene = shard::read_scene(Some(Path::new(&c1_scene()))).unwrap();
    scene
        .override_simulation(Some(1000), None, Some(1))
        .unwrap();
    let whole = lidarsim::pipeline::run(&scene).unwrap();
    let prepared = lidarsim::pipeline::prepare(&scene).unwrap();
    let watched = prepared
        .trace_until(&lidarsim::transport::quiet, &AtomicBool::new(false))
        .unwrap()
        .unwrap();
    assert_eq!(whole.mc.unwrap().returns, watched.returns);
    let stopped = prepared.trace_until(&lidarsim::transport::quiet, &AtomicBool::new(true));
    assert!(matches!(
        stopped,
        Err(lidarsim::pipeline::RunError::Transport(
            lidarsim::transport::TransportError::Stopped
        ))
    ));
}

/// `lidarsim dial SCENE --ensemble 4 --on on,side` (12 profiles, analytic) with extra
/// arguments, into `out`.
fn dial(scene: &Path, out: &Path, extra: &[&str]) -> String {
    let mut args = vec![
        "dial".to_string(),
        s(scene),
        "--out".into(),
        s(out),
        "--ensemble".into(),
        "4".into(),
        "--on".into(),
        "on,side".into(),
    ];
    args.extend(extra.iter().map(|a| a.to_string()));
    lidarsim_ok(&args)
}

/// The study scene of tests/study.rs in `dir`.
fn study_scene(dir: &Path) -> PathBuf {
    let p = dir.join("study.toml");
    fs::write(&p, crate::study::SCENE).unwrap();
    p
}

/// Three study shards in `dir/name`, each written by `study(out, extra)` (shard 1 on two
/// threads, the others on one) and reporting its slice of the profiles.
fn three_study_shards(
    dir: &Path,
    name: &str,
    extra: &[&str],
    study: impl Fn(&Path, &[&str]) -> String,
) -> Vec<PathBuf> {
    let out = dir.join(name);
    (0..3)
        .map(|i| {
            let spec = format!("{i}/3");
            let threads = if i == 1 { "2" } else { "1" };
            let mut a = vec!["--shard", &spec, "--threads", threads];
            a.extend_from_slice(extra);
            let stdout = study(&out, &a);
            assert!(
                stdout.contains(&format!("shard {i}/3: profiles")),
                "{stdout}"
            );
            out.join(format!("shard-{i}-of-3.lshard"))
        })
        .collect()
}

/// `lidarsim merge` of the three shards in `dir/shards` into `dir/merged`, the last moved to
/// another directory and given as a file; the merged directory and the merge's report.
fn merge_three(dir: &Path, shards: &[PathBuf]) -> (PathBuf, String) {
    fs::create_dir(dir.join("other")).unwrap();
    let moved = dir.join("other").join("shard-2-of-3.lshard");
    fs::rename(&shards[2], &moved).unwrap();
    let merged = dir.join("merged");
    let stdout = lidarsim_ok([
        "merge".to_string(),
        s(&dir.join("shards")),
        s(&moved),
        "--out".into(),
        s(&merged),
    ]);
    (merged, stdout)
}

/// Three dial shards of the study in `dir/name`.
fn three_dial_shards(scene: &Path, dir: &Path, name: &str, extra: &[&str]) -> Vec<PathBuf> {
    three_study_shards(dir, name, extra, |out, a| dial(scene, out, a))
}

/// A study merge refuses the three shards `base` with the last missing or with shard 1 given
/// twice (a copy in `dir`), and each `(name, extra, why)` of `cases`: the last shard made by
/// `shards(name, extra)` among the first two of `base`, refused with `why`, naming both files.
fn merge_refuses_missing_duplicated_and_other_options(
    dir: &Path,
    base: &[PathBuf],
    shards: impl Fn(&str, &[&str]) -> Vec<PathBuf>,
    cases: &[(&str, &[&str], &str)],
) {
    let e = merge_refused(&base[..2]);
    assert!(e.contains("1 of 3 shards missing (2)"), "{e}");
    let copy = dir.join("copy.lshard");
    fs::copy(&base[1], &copy).unwrap();
    let e = merge_refused(&[
        base[0].clone(),
        base[1].clone(),
        copy.clone(),
        base[2].clone(),
    ]);
    assert!(
        e.contains("shard 1/3 is given twice") && e.contains("copy.lshard"),
        "{e}"
    );
    for (name, extra, why) in cases {
        let other = shards(name, extra);
        let e = merge_refused(&[base[0].clone(), base[1].clone(), other[2].clone()]);
        assert!(e.contains(why), "{name}: {e}");
        assert!(e.contains(&s(&base[0])) && e.contains(&s(&other[2])), "{e}");
    }
}

/// Issue 12, item 1 for ensembles: one `lidarsim dial` and the merge of 3 dial shards give
/// byte-identical profiles.csv, summary.csv, budget.csv, failed.csv and figures, the same
/// summary.json but for its timing and the scene's path (absolute in shards), and profiles.nc
/// and summary.nc equal in every dimension, variable, attribute and value but `history`.
#[test]
fn dial_shards_merge_into_the_single_studys_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = study_scene(d);
    let single = d.join("single");
    dial(&scene, &single, &[]);
    let shards = three_dial_shards(&scene, d, "shards", &[]);
    let (merged, stdout) = merge_three(d, &shards);
    assert!(
        stdout.contains("merged 3 dial shards of 12 profiles"),
        "{stdout}"
    );
    let names = file_names(&single);
    for f in [
        "profiles.csv",
        "summary.csv",
        "budget.csv",
        "failed.csv",
        "summary.json",
        "ensemble.png",
        "profiles.nc",
        "summary.nc",
    ] {
        assert!(names.contains(&f.to_string()), "{f} in {names:?}");
    }
    assert_eq!(names, file_names(&merged));
    for name in &names {
        if let Some(variable) = match name.as_str() {
            "profiles.nc" => Some("spectroscopy_ppm"),
            "summary.nc" => Some("total_budget_ppm"),
            _ => None,
        } {
            let (_, history) = assert_same_netcdf(&single.join(name), &merged.join(name), variable);
            assert!(history.contains("lidarsim merge"), "{history}");
            continue;
        }
        let (a, b) = (
            fs::read(single.join(name)).unwrap(),
            fs::read(merged.join(name)).unwrap(),
        );
        if name == "summary.json" {
            let strip = |bytes: &[u8]| {
                let mut v: serde_json::Value = serde_json::from_slice(bytes).unwrap();
                let o = v.as_object_mut().unwrap();
                for k in ["timing_s", "scene"] {
                    assert!(o.remove(k).is_some(), "summary.json has {k}");
                }
                v
            };
            assert_eq!(strip(&a), strip(&b), "summary.json");
        } else {
            assert!(a == b, "{name} differs between the study and the merge");
        }
    }
    // A shard's records are the same on any thread count (its header records its timing):
    // shard 1, on two threads above, again on one.
    let one = d.join("one");
    dial(&scene, &one, &["--shard", "1/3", "--threads", "1"]);
    let again = [one.join("shard-1-of-3.lshard")];
    let body = |p: &Path| {
        let f = lidarsim::study::shard::DialShardFile::read(p).unwrap();
        f.outcomes
    };
    assert_eq!(body(&again[0]), body(&shards[1]));
}

/// A dial merge refuses a missing or duplicated shard, shards of another seed, scene or
/// options, a run shard among dial shards and a damaged file: exit code 2, one line naming the
/// files, nothing written.
#[test]
fn dial_merge_refuses_foreign_missing_and_damaged_shards() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = study_scene(d);
    let base = three_dial_shards(&scene, d, "base", &[]);
    merge_refuses_missing_duplicated_and_other_options(
        d,
        &base,
        |name, extra| three_dial_shards(&scene, d, name, extra),
        &[
            ("seed", &["--seed", "5"], "the seed differs (3 against 5)"),
            (
                "steps",
                &["--budget-temperature-k", "2"],
                "the set of budget steps differs",
            ),
            ("pairs", &["--on", "on"], "the choice of line pairs differs"),
        ],
    );
    let other_scene = d.join("other.toml");
    fs::write(
        &other_scene,
        crate::study::SCENE.replace("co2_ppm = 420.0", "co2_ppm = 410.0"),
    )
    .unwrap();
    let other = three_dial_shards(&other_scene, d, "scene", &[]);
    let e = merge_refused(&[base[0].clone(), base[1].clone(), other[2].clone()]);
    assert!(
        e.contains("the scene (digest) differs") && e.contains("other.toml"),
        "{e}"
    );

    // A run shard among dial shards.
    let run_dir = d.join("run");
    shard(
        Some(&c1_scene()),
        "0/4",
        &run_dir,
        &["--photons", "400", "--threads", "1"],
    );
    let run_shard = run_dir.join("shard-0-of-4.lshard");
    let e = merge_refused(&[base[0].clone(), run_shard.clone()]);
    assert!(
        e.contains("kind of shard") && e.contains("dial against run"),
        "{e}"
    );
    assert!(e.contains(&s(&run_shard)), "{e}");

    // Damage: one flipped byte in the records, a truncation.
    let mut bytes = fs::read(&base[1]).unwrap();
    let n = bytes.len();
    bytes[n - 20] ^= 1;
    let flipped = d.join("flipped.lshard");
    fs::write(&flipped, &bytes).unwrap();
    let e = merge_refused(&[base[0].clone(), flipped.clone(), base[2].clone()]);
    assert!(e.contains("corrupt") && e.contains(&s(&flipped)), "{e}");
    let cut = d.join("cut.lshard");
    fs::write(&cut, &bytes[..n / 2]).unwrap();
    let e = merge_refused(&[base[0].clone(), cut.clone(), base[2].clone()]);
    assert!(e.contains(&s(&cut)), "{e}");

    // No more shards than profiles, refused before any work.
    let o = lidarsim([
        "dial".to_string(),
        s(&scene),
        "--ensemble".into(),
        "4".into(),
        "--shard".into(),
        "12/13".into(),
        "--out".into(),
        s(&d.join("too_many")),
    ]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("13 shards of a study of 12 profiles"), "{e}");
    assert!(!e.contains("panicked"), "{e}");
}

/// Dial shards of a profile set file: the merge gives the single study's tables, and refuses a
/// set file that changed since the shards ran, naming it.
#[test]
fn dial_shards_of_a_profile_set_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = study_scene(d);
    let set = d.join("set.csv");
    let generate = |seed: &str| {
        lidarsim_ok([
            "profiles",
            "generate",
            "--n",
            "5",
            "--seed",
            seed,
            "--class",
            "mid",
            "--out",
            &s(&set),
        ]);
    };
    generate("2");
    let study = |out: &Path, extra: &[&str]| {
        let mut a = vec![
            "dial".to_string(),
            s(&scene),
            "--profiles".into(),
            s(&set),
            "--no-plots".into(),
            "--out".into(),
            s(out),
        ];
        a.extend(extra.iter().map(|x| x.to_string()));
        lidarsim_ok(&a);
    };
    let single = d.join("single");
    study(&single, &[]);
    let shards = d.join("shards");
    for spec in ["0/2", "1/2"] {
        study(&shards, &["--shard", spec]);
    }
    let merged = d.join("merged");
    lidarsim_ok([
        "merge".to_string(),
        s(&shards),
        "--no-plots".into(),
        "--out".into(),
        s(&merged),
    ]);
    for f in ["profiles.csv", "summary.csv", "budget.csv", "failed.csv"] {
        assert!(
            fs::read(single.join(f)).unwrap() == fs::read(merged.join(f)).unwrap(),
            "{f}"
        );
    }
    generate("3");
    let e = merge_refused(&[shards]);
    assert!(
        e.contains("is not the one the shards ran") && e.contains("set.csv"),
        "{e}"
    );
}

/// `lidarsim select-lines ARGS --out OUT EXTRA…`.
fn select_lines_with(args: &[&str], out: &Path, extra: &[&str]) -> String {
    let mut a = vec!["select-lines".to_string()];
    a.extend(args.iter().map(|x| x.to_string()));
    a.extend(["--out".to_string(), s(out)]);
    a.extend(extra.iter().map(|x| x.to_string()));
    lidarsim_ok(&a)
}

/// `lidarsim select-lines` on generated ensembles of 2 members per class (6 members), with
/// per-profile rows, a 21-position scan on a 2 km grid to 30 km and the figures of R4e
/// (0.1 s), with extra arguments, into `out`.
fn select_lines(out: &Path, extra: &[&str]) -> String {
    let args = [
        "--ensemble",
        "2",
        "--per-profile",
        "--max-j",
        "6",
        "--offsets-ghz=-1,1,2",
        "--off-cm1",
        "6360.61",
        "--co2-ppm",
        "420",
        "--layer-m",
        "2000",
        "--top-km",
        "30",
        "--figure-lines",
        "R4e",
    ];
    select_lines_with(&args, out, extra)
}

/// Three select-lines shards in `dir/name`.
fn three_select_shards(dir: &Path, name: &str, extra: &[&str]) -> Vec<PathBuf> {
    three_study_shards(dir, name, extra, select_lines)
}

/// Two NetCDF files with the same dimensions, variables, attributes and values (each f64 by
/// its shortest exact decimal), read by the `netcdf3` crate's reader, but for the global
/// attribute `history` (the time and the command line); `variable` is one of them. Returns the
/// two histories.
fn assert_same_netcdf(a: &Path, b: &Path, variable: &str) -> (String, String) {
    let read = |p: &Path| {
        let mut r = netcdf3::FileReader::open(p).unwrap();
        let mut vars: Vec<_> = r.read_all_vars().unwrap().into_iter().collect();
        vars.sort_by(|x, y| x.0.cmp(&y.0));
        let (mut ds, version) = r.close();
        let history = ds.get_global_attr_as_string("history").unwrap();
        ds.remove_global_attr("history").unwrap();
        (format!("{version:?} {ds:?}"), format!("{vars:?}"), history)
    };
    let (ha, va, hist_a) = read(a);
    let (hb, vb, hist_b) = read(b);
    assert_eq!(ha, hb, "{} and {}: header", a.display(), b.display());
    assert!(va == vb, "{} and {}: values", a.display(), b.display());
    assert!(va.contains(&format!("{variable:?}")), "{variable} in {va}");
    (hist_a, hist_b)
}

/// The report of a select-lines run without the lines that name the run (`merged …`, the
/// setup line, `wrote …`).
fn group_report(stdout: &str) -> Vec<&str> {
    stdout
        .lines()
        .filter(|l| !l.starts_with("merged ") && !l.starts_with("wrote "))
        .collect()
}

/// Issue 12, item 1 for line selection: one `lidarsim select-lines` and the merge of 3 shards
/// (one given as a file of another directory, one run on two threads) give byte-identical
/// sensitivities.csv and figures, a sensitivities.nc equal in every dimension, variable,
/// attribute and value but `history`, and the same report. A shard's results are the same on
/// any thread count.
#[test]
fn select_lines_shards_merge_into_the_single_studys_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let single = d.join("single");
    let single_stdout = select_lines(&single, &["--threads", "2"]);
    let shards = three_select_shards(d, "shards", &[]);
    let (merged, stdout) = merge_three(d, &shards);
    assert!(
        stdout.contains("merged 3 select-lines shards of 6 profiles"),
        "{stdout}"
    );
    assert_eq!(group_report(&stdout), group_report(&single_stdout));
    let names = file_names(&single);
    assert_eq!(names, file_names(&merged));
    for c in ["tropical", "mid", "high"] {
        for f in [format!("transmission_{c}.png"), format!("errors_{c}.png")] {
            assert!(names.contains(&f), "{f} in {names:?}");
        }
    }
    for name in &names {
        let (a, b) = (single.join(name), merged.join(name));
        if name == "sensitivities.nc" {
            let (_, history) = assert_same_netcdf(&a, &b, "dxco2_per_k_ppm");
            assert!(history.contains("lidarsim merge"), "{history}");
        } else {
            assert!(
                fs::read(&a).unwrap() == fs::read(&b).unwrap(),
                "{name} differs between the study and the merge"
            );
        }
    }
    // 3 classes × 21 positions and 6 profiles × 21 positions.
    let csv = fs::read_to_string(single.join("sensitivities.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 9 * 21);

    // Shard 1, on two threads above, again on one: the same results.
    let one = d.join("one");
    select_lines(&one, &["--shard", "1/3", "--threads", "1"]);
    let body = |p: &Path| {
        let f = lidarsim::study::select_shard::SelectShardFile::read(p).unwrap();
        assert_eq!(f.outcomes.len(), 2);
        format!("{:?}", f.outcomes)
    };
    assert_eq!(body(&one.join("shard-1-of-3.lshard")), body(&shards[1]));
}

/// A select-lines merge refuses a missing or duplicated shard, shards of another seed or
/// options, shards of other kinds among them and a damaged file: exit code 2, one line
/// naming the files, nothing written. More shards than profiles are refused before any work.
#[test]
fn select_lines_merge_refuses_foreign_missing_and_damaged_shards() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let base = three_select_shards(d, "base", &[]);
    merge_refuses_missing_duplicated_and_other_options(
        d,
        &base,
        |name, extra| three_select_shards(d, name, extra),
        &[
            ("seed", &["--seed", "5"], "the seed differs (1 against 5)"),
            (
                "wing",
                &["--wing-cm1", "20"],
                "the wing cutoff (--wing-cm1) differs (25 against 20)",
            ),
            (
                "plots",
                &["--no-plots"],
                "the choice of figures (--no-plots, --figure-lines) differs",
            ),
            (
                "uncertainty",
                &["--temperature-uncertainty-k", "0.5"],
                "the set of uncertainties (K, MHz, hPa, %) differs (1,1,1,10 against 0.5,1,1,10)",
            ),
        ],
    );

    // A dial shard and a run shard among select shards.
    let scene = study_scene(d);
    let dial_shard = three_dial_shards(&scene, d, "dial", &[]).remove(0);
    let e = merge_refused(&[base[0].clone(), base[1].clone(), dial_shard.clone()]);
    assert!(
        e.contains("kind of shard") && e.contains("select against dial"),
        "{e}"
    );
    assert!(e.contains(&s(&dial_shard)), "{e}");
    let run_dir = d.join("run");
    shard(
        Some(&c1_scene()),
        "0/4",
        &run_dir,
        &["--photons", "400", "--threads", "1"],
    );
    let run_shard = run_dir.join("shard-0-of-4.lshard");
    let e = merge_refused(&[run_shard.clone(), base[0].clone()]);
    assert!(
        e.contains("run against select") && e.contains(&s(&run_shard)),
        "{e}"
    );
    // The library refuses a select shard where it reads a dial shard.
    let e = lidarsim::study::shard::DialShardFile::read(&base[0]).unwrap_err();
    assert!(
        e.to_string()
            .contains("a `select` shard (from `lidarsim select-lines --shard`), not a dial shard"),
        "{e}"
    );

    // Damage: a flipped byte in the results, a truncation, a header whose range is not its
    // shard's (with a correct checksum), bytes beyond the end.
    let good = fs::read(&base[1]).unwrap();
    let n = good.len();
    let mut flipped = good.clone();
    flipped[n - 20] ^= 1;
    for (name, bytes, why) in [
        ("flipped", flipped, "corrupt: checksum"),
        ("cut", good[..n / 2].to_vec(), "corrupt"),
        (
            "range",
            with_header(&good, |h| h["end_profile"] = 5.into()),
            "inconsistent header: profiles 2..5 as shard 1/3 of 6 profiles",
        ),
        (
            "tail",
            with_header(&[&good, &[0u8; 8][..]].concat(), |_| {}),
            "8 bytes beyond its last profile",
        ),
    ] {
        let p = d.join(format!("{name}.lshard"));
        fs::write(&p, bytes).unwrap();
        let e = merge_refused(&[base[0].clone(), p.clone(), base[2].clone()]);
        assert!(e.contains(why) && e.contains(&s(&p)), "{name}: {e}");
    }

    // No more shards than profiles, refused before any work.
    let out = d.join("too_many");
    let o = lidarsim([
        "select-lines",
        "--ensemble",
        "2",
        "--off-cm1",
        "6360.61",
        "--co2-ppm",
        "420",
        "--shard",
        "6/7",
        "--out",
        &s(&out),
    ]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("7 shards of a study of 6 profiles"), "{e}");
    assert!(!e.contains("panicked") && !out.exists(), "{e}");
}

/// Select-lines shards of a profile set file (one profile that cannot be studied) and of a
/// HITRAN line file: the merge gives the single study's files and report, and refuses the set
/// file or the line file changed since the shards ran, naming it.
#[test]
fn select_lines_shards_of_a_profile_set_and_a_line_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Two tropical profiles and `short`, which ends at 700 hPa, below one 4 km layer
    // (tests/select_lines.rs).
    let set = d.join("set.csv");
    let text = crate::select_lines::tropical_set(&[
        ("a", 10.0, 0.0, 10),
        ("short", 5.0, 0.0, 3),
        ("b", -12.0, 2.0, 10),
    ]);
    fs::write(&set, &text).unwrap();
    let set_arg = s(&set);
    let args = [
        "--profiles",
        &set_arg,
        "--per-profile",
        "--max-j",
        "18",
        "--offsets-ghz=1.5,2",
        "--off-cm1",
        "6360.61",
        "--co2-ppm",
        "410",
        "--layer-m",
        "4000",
        "--top-km",
        "40",
        "--figure-lines",
        "R16e",
    ];
    let study = |out: &Path, extra: &[&str]| select_lines_with(&args, out, extra);
    let single = d.join("single");
    let single_stdout = study(&single, &[]);
    assert!(
        single_stdout.contains("tropical: excluded 1 profile: "),
        "{single_stdout}"
    );
    let shards = d.join("shards");
    for spec in ["0/2", "1/2"] {
        study(&shards, &["--shard", spec]);
    }
    let merged = d.join("merged");
    let stdout = lidarsim_ok(["merge".to_string(), s(&shards), "--out".into(), s(&merged)]);
    assert_eq!(group_report(&stdout), group_report(&single_stdout));
    let names = file_names(&single);
    assert_eq!(names, file_names(&merged));
    for name in names.iter().filter(|n| *n != "sensitivities.nc") {
        assert!(
            fs::read(single.join(name)).unwrap() == fs::read(merged.join(name)).unwrap(),
            "{name}"
        );
    }
    assert_same_netcdf(
        &single.join("sensitivities.nc"),
        &merged.join("sensitivities.nc"),
        "dxco2_per_k_ppm",
    );
    // `--no-plots` at the merge leaves out the figures only.
    let plain = d.join("plain");
    lidarsim_ok([
        "merge".to_string(),
        s(&shards),
        "--no-plots".into(),
        "--out".into(),
        s(&plain),
    ]);
    assert_eq!(
        file_names(&plain),
        ["failed.csv", "sensitivities.csv", "sensitivities.nc"]
    );
    assert!(
        fs::read(single.join("sensitivities.csv")).unwrap()
            == fs::read(plain.join("sensitivities.csv")).unwrap()
    );

    fs::write(&set, text.replace("b,-12,0,850,292,", "b,-12,0,850,292.5,")).unwrap();
    assert_ne!(fs::read_to_string(&set).unwrap(), text);
    let e = merge_refused(std::slice::from_ref(&shards));
    assert!(
        e.contains("are not the ones the shards ran") && e.contains("set.csv"),
        "{e}"
    );

    // A line file: the CO2 lines of HITRAN 2016 from 6330 to 6390 cm-1.
    let Some(hitran) = crate::util::shared_file("data/hitran/CO2_626_6000-6400_HITRAN2016.par")
    else {
        return;
    };
    let lines_file = d.join("co2.par");
    let window = crate::util::par_records_in(&hitran, 6330.0, 6390.0);
    fs::write(&lines_file, &window).unwrap();
    let lines_arg = s(&lines_file);
    let args = [
        "--atmosphere",
        "us_standard,tropical,subarctic_winter",
        "--lines",
        &lines_arg,
        "--on-cm1",
        "6360.0337,6362.4704",
        "--off-cm1",
        "6360.61",
        "--co2-ppm",
        "420",
        "--layer-m",
        "2000",
        "--top-km",
        "30",
        "--no-plots",
    ];
    let study = |out: &Path, extra: &[&str]| select_lines_with(&args, out, extra);
    let single = d.join("lines_single");
    study(&single, &[]);
    let shards = d.join("lines_shards");
    for spec in ["0/3", "1/3", "2/3"] {
        study(&shards, &["--shard", spec]);
    }
    let merged = d.join("lines_merged");
    lidarsim_ok(["merge".to_string(), s(&shards), "--out".into(), s(&merged)]);
    assert!(
        fs::read(single.join("sensitivities.csv")).unwrap()
            == fs::read(merged.join("sensitivities.csv")).unwrap()
    );
    // The intensity of R16e of the 30012 band (columns 16-25, ` 1.779E-23`) changed in its
    // last digit.
    let r16 = window
        .lines()
        .find(|l| l.contains("R 16e") && l.get(21..25) == Some("E-23"))
        .unwrap();
    let mut changed = r16.as_bytes().to_vec();
    changed[20] = b'0' + (changed[20] - b'0' + 1) % 10;
    let changed = String::from_utf8(changed).unwrap();
    fs::write(&lines_file, window.replacen(r16, &changed, 1)).unwrap();
    let e = merge_refused(&[shards]);
    assert!(
        e.contains("the line list as read now") && e.contains("co2.par"),
        "{e}"
    );
}

/// `bytes` (a shard file) with the 8 bytes at `at` replaced by `value` and a correct checksum:
/// a file whose framing is sound and whose numbers are not.
fn with_bits(bytes: &[u8], at: usize, value: u64) -> Vec<u8> {
    let mut out = bytes.to_vec();
    out[at..at + 8].copy_from_slice(&value.to_le_bytes());
    with_checksum(out)
}

/// Where the batch records of a run shard start, how long one is, and its tallies per batch
/// (returns bins, flux channels), from its header.
fn run_layout(bytes: &[u8]) -> (usize, usize, usize, usize) {
    let len = u64::from_le_bytes(bytes[20..28].try_into().unwrap()) as usize;
    let h: serde_json::Value = serde_json::from_slice(&bytes[28..28 + len]).unwrap();
    let bins = h["bins_per_batch"].as_u64().unwrap() as usize;
    let ch = h["channels"].as_u64().unwrap() as usize;
    (28 + len, 8 * (10 + bins + 4 * ch), bins, ch)
}

/// Issue 37, item 5: a merge checks the numbers of a run shard, not only its checksum. A
/// shard (C.1, unpolarised) whose returns or flux tally holds NaN, ±inf or −1e300, whose
/// photon counter is not the batches', or whose wall time is negative or NaN, each with a
/// correct checksum, is refused with the file and the batch named; nothing is written.
#[test]
fn merge_refuses_shards_whose_tallies_are_not_energies() {
    let dir = tempfile::tempdir().unwrap();
    let files = four_shards(&dir.path().join("a"), &[]);
    let good = fs::read(&files[1]).unwrap();
    let (records, rec, bins, _) = run_layout(&good);
    // Shard 1 of 4 of C.1's 100 batches holds batches 25..50; its second record is batch 26.
    let second = records + rec;
    let tally = |i: usize| second + 8 * (10 + i);
    let n = good.len();
    let bits = f64::to_bits;
    let cases: Vec<(&str, Vec<u8>, String)> = vec![
        (
            "nan",
            with_bits(&good, tally(5), bits(f64::NAN)),
            format!("batch 26: returns tally 5 of {bins} is NaN: a tally is a finite number"),
        ),
        (
            "inf",
            with_bits(&good, tally(bins - 1), bits(f64::INFINITY)),
            format!("batch 26: returns tally {} of {bins} is inf", bins - 1),
        ),
        (
            "negative",
            with_bits(&good, tally(3), bits(-1e300)),
            format!("batch 26: returns tally 3 of {bins} is -1e300: an energy is never negative"),
        ),
        (
            "flux",
            with_bits(&good, tally(bins), bits(-1.0)),
            "batch 26: flux tally `up` of channel 0 is -1: an energy is never negative".into(),
        ),
        (
            "photons",
            with_bits(&good, second + 8, 3),
            "batch 26: 3 photons counted where each batch traces 4".into(),
        ),
        (
            "wall",
            with_bits(&good, n - 24, bits(-1.0)),
            "its wall time is -1 s: a time is a finite number ≥ 0".into(),
        ),
        (
            "wall_nan",
            with_bits(&good, n - 24, bits(f64::NAN)),
            "its wall time is NaN s".into(),
        ),
    ];
    let bad = dir.path().join("bad");
    fs::create_dir(&bad).unwrap();
    for (name, bytes, why) in cases {
        let p = bad.join(format!("{name}.lshard"));
        fs::write(&p, bytes).unwrap();
        let e = merge_refused(&[
            files[0].clone(),
            p.clone(),
            files[2].clone(),
            files[3].clone(),
        ]);
        assert!(e.contains(&why) && e.contains(&s(&p)), "{name}: {e}");
        fs::remove_file(&p).unwrap();
    }
}

/// With polarised light each returns bin is a co- or cross-polarised energy: −1e-300 where the
/// bin's co + cross is 0 is refused, naming file and batch; a cross-polarised energy of −1e-15
/// times the bin's intensity (rounding of (I − Q)/2) is accepted, and the merge writes files
/// without `NaN` or `inf`.
#[test]
fn merge_checks_polarised_tallies_up_to_rounding() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("pol.toml");
    fs::write(&scene, crate::output::POLARISED_CLOUD).unwrap();
    let shards = dir.path().join("shards");
    for i in 0..2 {
        shard(
            Some(&s(&scene)),
            &format!("{i}/2"),
            &shards,
            &["--threads", "1"],
        );
    }
    let path = shards.join("shard-1-of-2.lshard");
    let good = fs::read(&path).unwrap();
    let (records, _, bins, ch) = run_layout(&good);
    assert_eq!(ch, 1);
    let value =
        |i: usize| f64::from_le_bytes(good[records + 80 + 8 * i..][..8].try_into().unwrap());
    // (co, cross) pairs: one with no return, one with a return.
    let empty = (0..bins / 2)
        .find(|g| value(2 * g) == 0.0 && value(2 * g + 1) == 0.0)
        .unwrap();
    let lit = (0..bins / 2).find(|g| value(2 * g) > 0.0).unwrap();
    let at = |i: usize| records + 80 + 8 * i;
    fs::write(
        &path,
        with_bits(&good, at(2 * empty + 1), (-1e-300f64).to_bits()),
    )
    .unwrap();
    let e = merge_refused(std::slice::from_ref(&shards));
    assert!(
        e.contains(&format!(
            "batch 50: returns tally {} of {bins} is -1e-300: a co- or cross-polarised energy is never negative",
            2 * empty + 1
        )) && e.contains(&s(&path)),
        "{e}"
    );
    let tiny = -1e-15 * value(2 * lit);
    fs::write(&path, with_bits(&good, at(2 * lit + 1), tiny.to_bits())).unwrap();
    let out = dir.path().join("merged");
    lidarsim_ok([
        "merge".to_string(),
        s(&shards),
        "--no-plots".into(),
        "--out".into(),
        s(&out),
    ]);
    crate::util::assert_no_non_finite(&out);
}

/// Dial and select-lines shards: a record whose retrieved XCO2 is NaN (the noisy value alone
/// may be undefined), a negative random error, a negative or NaN time in the header, each with
/// a correct checksum, are refused with the file and the profile named.
#[test]
fn merge_refuses_study_shards_with_impossible_values() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = study_scene(d);
    let base = three_dial_shards(&scene, d, "base", &[]);
    let good = fs::read(&base[1]).unwrap();
    let file = lidarsim::study::shard::DialShardFile::parse(&base[1], &good).unwrap();
    let o = &file.outcomes[0];
    let r = &o.records.as_ref().unwrap()[0];
    // The record's values are unique bit patterns in the body: find them there.
    let find = |v: f64| {
        let b = v.to_le_bytes();
        let at: Vec<usize> = (0..good.len() - 8)
            .filter(|i| good[*i..*i + 8] == b)
            .collect();
        assert_eq!(at.len(), 1, "{v}");
        at[0]
    };
    let cases: Vec<(&str, Vec<u8>, String)> = vec![
        (
            "retrieved",
            with_bits(&good, find(r.retrieved_ppm), f64::NAN.to_bits()),
            format!("profile {}, {} ipda", o.id, r.pair),
        ),
        (
            "random",
            with_bits(&good, find(r.budget_ppm[0]), (-1.0f64).to_bits()),
            "random_ppm is -1: a standard deviation is never negative".into(),
        ),
        (
            "timing",
            with_header(&good, |h| h["timing_s"][5] = (-2.5).into()),
            "its wall time is -2.5 s".into(),
        ),
    ];
    for (name, bytes, why) in cases {
        let p = d.join(format!("{name}.lshard"));
        fs::write(&p, bytes).unwrap();
        let e = merge_refused(&[base[0].clone(), p.clone(), base[2].clone()]);
        assert!(e.contains(&why) && e.contains(&s(&p)), "{name}: {e}");
    }
    let select = three_select_shards(d, "select", &[]);
    let bytes = with_header(&fs::read(&select[0]).unwrap(), |h| {
        h["wall_s"] = (-1.0).into()
    });
    let p = d.join("select_wall.lshard");
    fs::write(&p, bytes).unwrap();
    let e = merge_refused(&[p.clone(), select[1].clone(), select[2].clone()]);
    assert!(
        e.contains("its wall time is -1 s") && e.contains(&s(&p)),
        "{e}"
    );
}

/// C.1 (absolute phase-table path) with a pulse of 0.5 J, a receiver of efficiency 0.4 and a
/// telescope of 0.8 m, in `dir`: the receiver gets at most 0.5 × 0.4 = 0.2 J.
fn c1_weak_receiver(dir: &Path) -> PathBuf {
    let text = fs::read_to_string(c1_scene()).unwrap();
    for key in [
        "pulse_energy_j = 1.0",
        "optical_efficiency = 1.0",
        "telescope_diameter_m = 1.0",
    ] {
        assert!(text.contains(key), "{key}");
    }
    let text = text
        .replace("pulse_energy_j = 1.0", "pulse_energy_j = 0.5")
        .replace("optical_efficiency = 1.0", "optical_efficiency = 0.4")
        .replace("telescope_diameter_m = 1.0", "telescope_diameter_m = 0.8")
        .replace(
            "../phase_functions/",
            &format!("{}/", s(&project_root().join("phase_functions"))),
        );
    let scene = dir.join("weak.toml");
    fs::write(&scene, text).unwrap();
    scene
}

/// `bytes` (a run shard) with returns tally `bin` of every batch set to `value`, checksum right.
fn with_every_batch(bytes: &[u8], bin: usize, value: f64) -> Vec<u8> {
    let (records, rec, _, _) = run_layout(bytes);
    let n = (bytes.len() - 24 - records) / rec;
    let mut out = bytes.to_vec();
    for b in 0..n {
        out = with_bits(&out, records + b * rec + 8 * (10 + bin), value.to_bits());
    }
    out
}

/// Issue 37, item 5 (fuzz finding F10's last case): every shard's numbers finite and ≥ 0, their
/// fold not. A tally of the largest double in one batch (merged before into 3.5e305 J, "± inf
/// J") is refused, naming the shard, the batch and the channel: a batch of a run that conserves
/// energy exceeds 1e9 × its batches × the bound with a probability below 1e-9 (Markov).
/// Energy conservation: a channel's received energy, every gate, order and field of view
/// summed, never exceeds the pulse energy × the receiver's optical efficiency (0.2 J here, as
/// the scene's numbers give it): shards whose batches all put 1.1 × 0.2 J into one bin (the
/// Monte Carlo's own returns are about 1e-6 of it) are refused; 0.9 × 0.2 J merge.
#[test]
fn merge_refuses_folds_beyond_a_double_or_beyond_the_pulse() {
    let dir = tempfile::tempdir().unwrap();
    let scene = c1_weak_receiver(dir.path());
    let shards = dir.path().join("shards");
    for i in 0..2 {
        shard(
            Some(&s(&scene)),
            &format!("{i}/2"),
            &shards,
            &["--photons", "400", "--threads", "1"],
        );
    }
    let path = shards.join("shard-1-of-2.lshard");
    let good = fs::read(&path).unwrap();
    let (records, _, _, _) = run_layout(&good);
    // Batch 50, returns tally 0 (first gate, order 1, narrowest FOV) = the largest double.
    fs::write(
        &path,
        with_bits(&good, records + 8 * 10, f64::MAX.to_bits()),
    )
    .unwrap();
    let e = merge_refused(std::slice::from_ref(&shards));
    assert!(
        e.contains(&s(&path))
            && e.contains("channel `")
            && e.contains("its batch 50 receives")
            && e.contains("Markov's inequality"),
        "{e}"
    );
    // The bound, independently: E·η = 0.5 J × 0.4; a batch's tally t is t·E·η·A/photons J.
    let h: serde_json::Value = {
        let len = u64::from_le_bytes(good[20..28].try_into().unwrap()) as usize;
        serde_json::from_slice(&good[28..28 + len]).unwrap()
    };
    let per_batch = h["photons_per_batch"].as_u64().unwrap() as f64;
    let area_m2 = std::f64::consts::PI * 0.25 * 0.8 * 0.8;
    let limit_j = 0.5 * 0.4;
    let tally = |fraction: f64| fraction * limit_j * per_batch / (limit_j * area_m2);
    let first = shards.join("shard-0-of-2.lshard");
    let good0 = fs::read(&first).unwrap();
    let both = |fraction: f64| {
        fs::write(&first, with_every_batch(&good0, 0, tally(fraction))).unwrap();
        fs::write(&path, with_every_batch(&good, 0, tally(fraction))).unwrap();
    };
    both(1.1);
    let e = merge_refused(std::slice::from_ref(&shards));
    assert!(
        e.contains(".lshard")
            && e.contains("channel `")
            && e.contains("more than the 0.2 J the pulse sends through the receiver"),
        "{e}"
    );
    both(0.9);
    let out = dir.path().join("merged");
    lidarsim_ok([
        "merge".to_string(),
        s(&shards),
        "--no-plots".into(),
        "--out".into(),
        s(&out),
    ]);
    crate::util::assert_no_non_finite(&out);
}

/// Fuzz finding F11: a run shard whose stored scene text was changed (checksum recomputed) is
/// refused naming that shard, whichever shard it is: every shard's text is checked against its
/// digest, not only the first's.
#[test]
fn merge_names_the_shard_whose_scene_text_was_changed() {
    let dir = tempfile::tempdir().unwrap();
    let files = four_shards(&dir.path().join("a"), &[]);
    let good = fs::read(&files[2]).unwrap();
    let bad = dir.path().join("bad");
    fs::create_dir(&bad).unwrap();
    let edit = |from: &'static str, to: &'static str| {
        with_header(&good, move |h| {
            let t = h["scene_text"].as_str().unwrap().to_string();
            assert!(t.contains(from), "{from}");
            h["scene_text"] = t.replacen(from, to, 1).into();
        })
    };
    let cases = [
        (
            "parse",
            edit("seed = 1", "seed = 01"),
            "its scene text does not parse",
        ),
        (
            "digest",
            edit("seed = 1", "seed = 2"),
            "its scene text does not match its digest",
        ),
    ];
    for (name, bytes, why) in cases {
        let p = bad.join(format!("{name}.lshard"));
        fs::write(&p, bytes).unwrap();
        let e = merge_refused(&[
            files[0].clone(),
            files[1].clone(),
            p.clone(),
            files[3].clone(),
        ]);
        assert!(e.contains(why) && e.contains(&s(&p)), "{name}: {e}");
        fs::remove_file(&p).unwrap();
    }
}
