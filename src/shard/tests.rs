use super::*;

#[test]
fn shard_specs_parse_and_refuse() {
    assert_eq!(
        "3/8".parse::<ShardSpec>(),
        Ok(ShardSpec { index: 3, count: 8 })
    );
    assert_eq!(
        " 0 / 1 ".parse::<ShardSpec>(),
        Ok(ShardSpec { index: 0, count: 1 })
    );
    for bad in [
        "8/8", "0/0", "3", "a/4", "-1/4", "1/-4", "1/2/3", "", "0/10001",
    ] {
        assert!(bad.parse::<ShardSpec>().is_err(), "{bad}");
    }
}

/// The shards' batch ranges tile 0..B in order, none empty, sizes within one of each
/// other, and agree with `of_batch` for every batch.
#[test]
fn shards_tile_the_batches_and_agree_with_of_batch() {
    for batches in 1..=60 {
        for count in 1..=batches {
            let mut next = 0;
            let (mut small, mut large) = (usize::MAX, 0);
            for index in 0..count {
                let r = ShardSpec { index, count }.batches(batches);
                assert_eq!(r.start, next, "B {batches} N {count} shard {index}");
                assert!(r.end > r.start);
                small = small.min(r.len());
                large = large.max(r.len());
                for b in r.clone() {
                    assert_eq!(ShardSpec::of_batch(b, count, batches), index);
                }
                next = r.end;
            }
            assert_eq!(next, batches);
            assert!(large - small <= 1);
        }
    }
    // Large counts do not overflow.
    let r = ShardSpec {
        index: 9_999,
        count: 10_000,
    }
    .batches(10_000);
    assert_eq!(r, 9_999..10_000);
}

#[test]
fn file_names_sort_in_shard_order() {
    assert_eq!(
        ShardSpec {
            index: 3,
            count: 100
        }
        .file_name(),
        "shard-003-of-100.lshard"
    );
    assert_eq!(
        ShardSpec { index: 0, count: 4 }.file_name(),
        "shard-0-of-4.lshard"
    );
}

/// The digest is that of the scene as parsed: the same for the same scene read twice or
/// run on other threads, different for another seed, photon count or value.
#[test]
fn the_digest_follows_the_parsed_scene() {
    let a = Scene::default_scene().unwrap();
    let mut b = Scene::default_scene().unwrap();
    assert_eq!(scene_digest(&a), scene_digest(&b));
    b.override_simulation(None, None, Some(7)).unwrap();
    assert_eq!(scene_digest(&a), scene_digest(&b), "threads do not count");
    b.override_simulation(None, Some(2), None).unwrap();
    assert_ne!(scene_digest(&a), scene_digest(&b), "seed");
    let mut c = a.clone();
    c.override_simulation(Some(5000), None, None).unwrap();
    assert_ne!(scene_digest(&a), scene_digest(&c), "photons");
    let mut d = a.clone();
    d.lidar.telescope_diameter_m = f64::from_bits(d.lidar.telescope_diameter_m.to_bits() + 1);
    assert_ne!(scene_digest(&a), scene_digest(&d), "one ulp");
}
