//! The opponent bots a capture study runs (`--bots`), by name.

use lasertag_core::bots::BotKind;

pub(crate) fn bot_name(b: BotKind) -> &'static str {
    match b {
        BotKind::Wander => "wander",
        BotKind::Evade => "evade",
        BotKind::Idle => "idle",
    }
}

/// The bots run unless asked: the paper's two.
pub const DEFAULT_BOTS: &str = "wander,evade";

/// A comma-separated list of bots (`wander`, `evade`, `idle`), each once.
pub fn parse_bots(text: &str) -> Result<Vec<BotKind>, String> {
    let mut bots = Vec::new();
    for name in text.split(',').map(str::trim) {
        let bot = [BotKind::Wander, BotKind::Evade, BotKind::Idle]
            .into_iter()
            .find(|b| bot_name(*b) == name)
            .ok_or_else(|| format!("{name:?}: the bots are wander, evade and idle"))?;
        if bots.contains(&bot) {
            return Err(format!("{name} is listed twice"));
        }
        bots.push(bot);
    }
    Ok(bots)
}

/// The names of `bots`, comma-separated, as [`parse_bots`] reads them.
pub(super) fn bots_name(bots: &[BotKind]) -> String {
    bots.iter()
        .map(|b| bot_name(*b))
        .collect::<Vec<_>>()
        .join(",")
}
