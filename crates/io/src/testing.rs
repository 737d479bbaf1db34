//! Helpers shared by the readers' unit tests.

/// Checks that every input of `cases` is refused with a message holding its text;
/// `message` reads an input and returns the message of its error.
pub(crate) fn assert_refused<B: AsRef<[u8]>>(cases: &[(B, &str)], message: impl Fn(&[u8]) -> String) {
    for (bytes, expected) in cases {
        let text = message(bytes.as_ref());
        assert!(text.contains(expected), "expected '{expected}' in '{text}'");
    }
}
