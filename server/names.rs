//! What a player's name may be (docs/api.md, "Names people keep"): its canonical form and
//! the key under which look-alikes collide.
//!
//! A name is shown to everyone (the HUD, the end card, the leaderboard), so it may not carry
//! what changes how the text around it reads or hides part of itself: bidirectional
//! controls, zero-width and other invisible characters, line separators, tag characters.
//! It is normalised (NFKC, spaces collapsed) before it is counted or stored, so that a
//! name written two ways is one name. Two names whose Unicode confusables skeletons (UTS #39,
//! the `unicode-security` crate) agree, ignoring case, look alike: a claim on one holds
//! the other too, so nobody plays under a Cyrillic copy of someone's name.

use unicode_normalization::UnicodeNormalization;
use unicode_security::GeneralSecurityProfile;
use unicode_security::confusable_detection::skeleton;

/// The most characters a name has once normalised.
pub const MAX_NAME_CHARS: usize = 24;
/// The most characters a name may be sent with: NFKC can lengthen a character many times
/// over (U+FDFA is 18 characters), so what is normalised is bounded first.
const MAX_SENT_CHARS: usize = 64;

/// Why a name was refused; the message names the character (its code point) or the length.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NameError {
    #[error("name: must be 1 to {MAX_NAME_CHARS} characters (it has {0} once normalised)")]
    Length(usize),
    #[error("name: {what} (U+{code:04X}) may not be part of a name")]
    Character { what: &'static str, code: u32 },
}

/// A name as the server keeps it: normalised and checked (the fields are private so that no
/// other one exists).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Name {
    text: String,
    key: String,
}

impl Name {
    /// `sent`, normalised (NFKC, outer spaces trimmed, runs of spaces made one), or why it
    /// cannot be a name.
    pub fn parse(sent: &str) -> Result<Name, NameError> {
        let count = sent.chars().count();
        if count > MAX_SENT_CHARS {
            return Err(NameError::Length(count));
        }
        // Checked before normalising too: NFKC maps some invisible characters to nothing
        // or to a space, and the refusal should name what was sent.
        for c in sent.chars() {
            if let Some(what) = hidden(c) {
                return Err(NameError::Character {
                    what,
                    code: c as u32,
                });
            }
        }
        let mut text = String::with_capacity(sent.len());
        for c in sent.nfkc() {
            refuse(c)?;
            if c == ' ' && (text.is_empty() || text.ends_with(' ')) {
                continue;
            }
            text.push(c);
        }
        let text = text.trim_end().to_string();
        let count = text.chars().count();
        if count == 0 || count > MAX_NAME_CHARS {
            return Err(NameError::Length(count));
        }
        let key = key_of(&text);
        Ok(Name { text, key })
    }

    pub fn as_str(&self) -> &str {
        &self.text
    }

    /// What look-alikes share: the confusables skeleton of the name lower-cased, and again
    /// of that lower-cased (so that `VICTIM`, `Victim` and `viсtim` with a Cyrillic `с`
    /// meet). Case goes first: the skeleton of `I` is `l`, which would part `VICTIM` from
    /// `victim`.
    pub fn key(&self) -> &str {
        &self.key
    }
}

/// A name a person joins a match under: checked, and whether they showed the token of its
/// claim (only then does the match count for the name's statistics and rating).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct JoinName {
    pub name: Name,
    pub claimed: bool,
}

impl JoinName {
    /// A name nobody claimed (or a server that keeps no names).
    pub fn unclaimed(name: Name) -> JoinName {
        JoinName {
            name,
            claimed: false,
        }
    }
}

fn key_of(text: &str) -> String {
    let once: String = skeleton(&text.to_lowercase()).collect();
    skeleton(&once.to_lowercase()).collect()
}

/// What `c` is when it would hide or reorder text around it.
fn hidden(c: char) -> Option<&'static str> {
    Some(match c {
        '\u{061C}'
        | '\u{200E}'
        | '\u{200F}'
        | '\u{202A}'..='\u{202E}'
        | '\u{2066}'..='\u{2069}' => "a bidirectional control",
        '\n' | '\r' | '\u{0085}' | '\u{2028}' | '\u{2029}' => "a line separator",
        '\u{E0000}'..='\u{E007F}' => "a tag character",
        '\u{00AD}'
        | '\u{034F}'
        | '\u{115F}'
        | '\u{1160}'
        | '\u{17B4}'
        | '\u{17B5}'
        | '\u{180B}'..='\u{180F}'
        | '\u{200B}'..='\u{200D}'
        | '\u{2060}'..='\u{2064}'
        | '\u{3164}'
        | '\u{FE00}'..='\u{FE0F}'
        | '\u{FEFF}'
        | '\u{FFA0}'
        | '\u{E0100}'..='\u{E01EF}' => "an invisible character",
        c if c.is_control() => "a control character",
        _ => return None,
    })
}

/// `Err` when `c` (normalised) may not be in a name, naming what it is.
fn refuse(c: char) -> Result<(), NameError> {
    let what = match (c, hidden(c)) {
        (' ', _) => return Ok(()),
        (_, Some(what)) => what,
        (c, None) if c.is_whitespace() => "a space other than U+0020",
        (c, None) if c.is_ascii_graphic() => return Ok(()),
        // Letters, digits and marks of the world's scripts in common use (UTS #39's
        // Identifier_Status Allowed); symbols, emoji and private use are not names.
        (c, None) if c.identifier_allowed() => return Ok(()),
        _ => "a character that is not a letter, digit or ASCII punctuation",
    };
    Err(NameError::Character {
        what,
        code: c as u32,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refused(sent: &str) -> String {
        Name::parse(sent).expect_err(sent).to_string()
    }

    #[test]
    fn names_are_normalised() {
        assert_eq!(
            Name::parse("  ada   lovelace ").unwrap().as_str(),
            "ada lovelace"
        );
        // Full-width letters are NFKC's compatibility forms of ASCII.
        assert_eq!(Name::parse("ｖｉｃｔｉｍ").unwrap().as_str(), "victim");
        assert_eq!(Name::parse("Zoë").unwrap().as_str(), "Zoë");
        assert_eq!(Name::parse("Zoe\u{0308}").unwrap().as_str(), "Zoë");
        assert_eq!(Name::parse("李小龍").unwrap().as_str(), "李小龍");
    }

    #[test]
    fn lengths_are_counted_once_normalised() {
        assert!(Name::parse(&"a".repeat(24)).is_ok());
        assert!(refused(&"a".repeat(25)).contains("1 to 24"));
        assert!(refused("").contains("has 0"));
        assert!(refused("   ").contains("has 0"));
        assert!(refused(&"a".repeat(10_000)).contains("has 10000"));
        // One character NFKC makes 18 of: two are too many.
        assert!(Name::parse("\u{FDFA}").is_ok());
        assert!(refused("\u{FDFA}\u{FDFA}").contains("has 36"));
    }

    #[test]
    fn hidden_and_reordering_characters_are_refused() {
        for (sent, what) in [
            ("evil\u{202E}gnp", "bidirectional control (U+202E)"),
            ("a\u{2066}b\u{2069}", "bidirectional control (U+2066)"),
            ("vic\u{200B}tim", "invisible character (U+200B)"),
            ("vic\u{FEFF}tim", "invisible character (U+FEFF)"),
            ("ha\u{3164}", "invisible character (U+3164)"),
            ("one\u{2028}two", "line separator (U+2028)"),
            ("one\ntwo", "line separator (U+000A)"),
            ("flag\u{E0041}", "tag character (U+E0041)"),
            ("tab\there", "control character (U+0009)"),
            ("a\u{1680}b", "space other than U+0020 (U+1680)"),
            ("\u{1F600}", "not a letter"),
            ("\u{E000}", "not a letter"),
        ] {
            let message = refused(sent);
            assert!(message.contains(what), "{sent:?}: {message}");
        }
    }

    #[test]
    fn look_alikes_share_a_key() {
        let key = |s: &str| Name::parse(s).unwrap().key().to_string();
        // Cyrillic а, е, о, р, с, х look like Latin letters.
        assert_eq!(key("victim"), key("vi\u{0441}tim"));
        assert_eq!(key("paypal"), key("\u{0440}\u{0430}y\u{0440}\u{0430}l"));
        assert_eq!(key("Victim"), key("victim"));
        assert_eq!(key("VICTIM"), key("victim"));
        assert_eq!(key("a11"), key("all"));
        assert_eq!(key("rn"), key("m"));
        assert_ne!(key("victim"), key("victor"));
        assert_ne!(key("ada"), key("bob"));
    }
}
