//! Scenario-file errors in the user's words: serde's messages about TOML values ("invalid
//! type: string \"abc\", expected u32") rewritten in terms of the file ("expected a whole
//! number, got the string \"abc\""). One place for every mapping; a message it does not know
//! is kept as serde wrote it.
//!
//! | serde says | the file's terms |
//! |---|---|
//! | `invalid type: G, expected E` | `expected E', got G'` |
//! | `invalid value: G, expected E` | `expected E', got G'` |
//!
//! serde's "missing field `k`", "unknown field `k`, expected one of ..." and "unknown variant
//! `v`, expected one of ..." already name the key and are kept.
//!
//! Expected types: `u8`..`u64`, `usize` -> "a whole number >= 0"; `i8`..`i64` -> "a whole
//! number"; `f32`, `f64` -> "a number"; `a boolean` -> "true or false"; `a sequence` -> "an
//! array"; `struct X`, `a map` -> "a table". Got: `string "s"` -> `the string "s"`; `floating
//! point `x`` -> `the number x`; `integer `n`` -> `the whole number n`; `boolean `b`` -> `b`;
//! `sequence` -> "an array"; `map` -> "a table".

/// `message` (serde's, from the TOML deserializer) in the user's words (module docs).
pub(crate) fn user_words(message: &str) -> String {
    for head in ["invalid type: ", "invalid value: "] {
        if let Some(rest) = message.strip_prefix(head)
            && let Some((got, expected)) = rest.rsplit_once(", expected ")
        {
            return format!(
                "expected {}, got {}",
                expected_words(expected),
                got_words(got)
            );
        }
    }
    message.to_string()
}

fn expected_words(e: &str) -> String {
    match e {
        "u8" | "u16" | "u32" | "u64" | "u128" | "usize" => "a whole number >= 0".into(),
        "i8" | "i16" | "i32" | "i64" | "i128" | "isize" => "a whole number".into(),
        "f32" | "f64" => "a number".into(),
        "a boolean" | "bool" => "true or false".into(),
        "a sequence" => "an array".into(),
        "a map" => "a table".into(),
        _ if e.starts_with("struct ") => "a table".into(),
        _ => e.to_string(),
    }
}

fn got_words(g: &str) -> String {
    let unquote = |s: &str| s.trim_matches('`').to_string();
    if let Some(s) = g.strip_prefix("string ") {
        format!("the string {s}")
    } else if let Some(x) = g.strip_prefix("floating point ") {
        format!("the number {}", unquote(x))
    } else if let Some(n) = g.strip_prefix("integer ") {
        format!("the whole number {}", unquote(n))
    } else if let Some(b) = g.strip_prefix("boolean ") {
        unquote(b)
    } else {
        match g {
            "sequence" => "an array".into(),
            "map" => "a table".into(),
            _ => g.to_string(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::user_words;

    #[test]
    fn serde_messages_in_the_files_terms() {
        let cases = [
            (
                "invalid type: string \"abc\", expected u32",
                "expected a whole number >= 0, got the string \"abc\"",
            ),
            (
                "invalid type: floating point `12.5`, expected u32",
                "expected a whole number >= 0, got the number 12.5",
            ),
            (
                "invalid type: integer `3`, expected a boolean",
                "expected true or false, got the whole number 3",
            ),
            (
                "invalid value: integer `-1`, expected u32",
                "expected a whole number >= 0, got the whole number -1",
            ),
            ("missing field `j_kg_m2`", "missing field `j_kg_m2`"),
            ("something else", "something else"),
        ];
        for (serde, want) in cases {
            assert_eq!(user_words(serde), want);
        }
    }
}
