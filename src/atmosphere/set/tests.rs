use super::*;

#[test]
fn classes_follow_the_paper_boundaries() {
    use LatitudeClass::*;
    for (lat, c) in [
        (0.0, Tropical),
        (-29.9, Tropical),
        (30.0, Mid),
        (-50.0, Mid),
        (50.01, High),
        (-90.0, High),
    ] {
        assert_eq!(LatitudeClass::of_latitude_deg(lat), c, "{lat}");
    }
}

#[test]
fn time_format() {
    for ok in [
        "",
        "2007-02-20",
        "2007-02-20T06:00Z",
        "2014-01-05T06:00:00Z",
    ] {
        assert!(check_time(ok).is_ok(), "{ok}");
    }
    for bad in ["2007-2-20", "20070220", "2007-02-20T06:00", "yesterday"] {
        assert!(check_time(bad).is_err(), "{bad}");
    }
}

#[test]
fn number_format_is_short_and_exact_to_9_digits() {
    assert_eq!(fmt_num(1013.25), "1013.25");
    assert_eq!(fmt_num(0.1 + 0.2), "0.3");
    assert_eq!(fmt_num(-0.0), "0");
    assert_eq!(fmt_num(123456789.4), "123456789");
}
