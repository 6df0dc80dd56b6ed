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

/// Profile ids are text in the written set whatever they read as: an id that a CSV reader
/// would load as a number, a boolean or a missing value gets the apostrophe of
/// [`crate::output::csv_field`], one with a double quote is quoted (RFC 4180), and the reader
/// gives every id back as it was; a hand-written set without the marks reads as it is (but
/// for a leading apostrophe, which the rule doubles).
#[test]
fn profile_ids_that_read_as_numbers_round_trip_as_text() {
    let ids = ["1064", "NA", "true", "'q", "a\"b", "trop-0001", "-2.5e3"];
    let mut text = String::from("profile,latitude_deg,longitude_deg,pressure_hPa,temperature_K\n");
    // By hand, as the rule says: one apostrophe in front of an id that starts with one.
    for id in ids.map(|i| if i == "'q" { "''q" } else { i }) {
        text.push_str(&format!("{id},10,20,1000,290\n{id},10,20,500,260\n"));
    }
    let path = Path::new("ids.csv");
    let set = parse_profile_set(path, &text).unwrap();
    let got: Vec<&str> = set.members.iter().map(|m| m.meta.id.as_str()).collect();
    assert_eq!(got, ids);
    let written = set.to_csv().unwrap();
    let mut fields: Vec<String> = Vec::new();
    let mut r = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_reader(written.as_bytes());
    for rec in r.records() {
        let f = rec.unwrap()[0].to_string();
        if fields.last() != Some(&f) {
            fields.push(f);
        }
    }
    // As a standard CSV parser reads them: every field that would read as a number, a
    // boolean or a missing value starts with an apostrophe.
    assert_eq!(
        fields,
        [
            "'1064",
            "'NA",
            "'true",
            "''q",
            "a\"b",
            "trop-0001",
            "'-2.5e3"
        ]
    );
    let back = parse_profile_set(path, &written).unwrap();
    let back: Vec<&str> = back.members.iter().map(|m| m.meta.id.as_str()).collect();
    assert_eq!(back, ids);
}
