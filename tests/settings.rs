//! The words each front end gives the library's settings.

use rdlidar::settings::{FrontEnd, SETTINGS};
use rdlidar::Error;

#[test]
fn settings_take_each_front_ends_words() {
    use FrontEnd::*;
    assert_eq!(CommandLine.word("pulse_len"), "--pulse-len");
    assert_eq!(Python.word("pulse_len"), "pulse_len");
    assert_eq!(CommandLine.word("force"), "--force");
    assert_eq!(Python.word("force"), "force=True");
    assert_eq!(CommandLine.word("precision"), "--precision");
    assert_eq!(Python.word("precision"), "dtype");
    assert_eq!(CommandLine.word("method"), "--solver");
    assert_eq!(CommandLine.word("RDLIDAR_ISA"), "RDLIDAR_ISA");
    assert_eq!(Python.word("RDLIDAR_MEMORY_LIMIT"), "RDLIDAR_MEMORY_LIMIT");
    for s in SETTINGS {
        assert!(!s.name.is_empty() && !s.argument.is_empty(), "{s:?}");
        assert!(CommandLine.word(s.name).ends_with(s.flag), "{s:?}");
        assert_eq!(Python.word(s.name), s.argument);
    }
}

#[test]
fn only_settings_between_backticks_are_rendered() {
    let text = "`adcs` 2 and `tiles` 2x2; run `simulate --codes-format seed`; `A` and `";
    assert_eq!(
        FrontEnd::CommandLine.words(text),
        "--adcs 2 and --tiles 2x2; run `simulate --codes-format seed`; `A` and `"
    );
    assert_eq!(
        FrontEnd::Python.words(text),
        "adcs 2 and tiles 2x2; run `simulate --codes-format seed`; `A` and `"
    );
    let e = Error::File {
        path: "x".into(),
        reason: "not empty: `force` replaces it".into(),
    };
    assert!(FrontEnd::Python
        .render(&e)
        .ends_with("force=True replaces it"));
    assert!(FrontEnd::CommandLine
        .render(&e)
        .ends_with("--force replaces it"));
    let text = "applies only to `scene=png`, not to `scene=paper`; `adcs=2`; `tiles=2x2`";
    assert_eq!(
        FrontEnd::CommandLine.words(text),
        "applies only to --scene png, not to --scene paper; --adcs 2; --tiles 2x2"
    );
    assert_eq!(
        FrontEnd::Python.words(text),
        "applies only to scene=\"png\", not to scene=\"paper\"; adcs=2; tiles=\"2x2\""
    );
    let e = Error::InvalidParameter {
        name: "out",
        reason: "needs `force`".into(),
    };
    assert_eq!(FrontEnd::CommandLine.render(&e), "--out: needs --force");
    assert_eq!(FrontEnd::Python.render(&e), "out: needs force=True");
}
