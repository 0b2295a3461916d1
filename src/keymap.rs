//! Every keyboard shortcut of the page, written once: the handlers look keys up here
//! ([`command`]), the help panel lists [`KEYMAP`], and tooltips take their keys from
//! [`tooltip`].

/// Where a key acts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scope {
    /// Anywhere on the page, except while typing in a field.
    Page,
    /// On a focused view (canvas).
    View,
    /// On the focused radiograph of the background composer.
    Region,
    /// On the focused source tabs.
    Tabs,
    /// On the focused 3D view of the catheter.
    Scene,
}

/// What a key does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// Run H-Net on the pair on screen.
    RunModel,
    /// Use H-Net's masks as the labels.
    AcceptMasks,
    /// The brush.
    Brush,
    /// The eraser.
    Eraser,
    /// The pan tool.
    Pan,
    /// The window/level tool (drag on a DICOM frame).
    WindowLevel,
    /// Play or pause the cine.
    PlayPause,
    /// The cine's next frame.
    NextFrame,
    /// The cine's previous frame.
    PreviousFrame,
    /// A smaller brush.
    SmallerBrush,
    /// A larger brush.
    LargerBrush,
    /// Undo the last mask edit.
    Undo,
    /// Redo it.
    Redo,
    /// Show or hide H-Net's masks.
    ToggleMasks,
    /// Show or hide the labels.
    ToggleLabels,
    /// Fit both views.
    FitViews,
    /// The next pair.
    NextPair,
    /// The previous pair.
    PreviousPair,
    /// Move left (a view's picture, the region), or to the previous tab.
    Left,
    /// Move right, or to the next tab.
    Right,
    /// Move up.
    Up,
    /// Move down.
    Down,
    /// Zoom in, or enlarge the region.
    Grow,
    /// Zoom out, or shrink the region.
    Shrink,
    /// The first tab.
    First,
    /// The last tab.
    Last,
    /// Back to the 3D view's first angles and framing.
    ResetView,
    /// Switch the 3D view between perspective and orthographic projection.
    ToggleProjection,
}

/// One key press that triggers a command: the key (as `KeyboardEvent.key`, compared without
/// case), whether Ctrl (or ⌘) is held, and whether Shift must be held (`Some(true)`), must not
/// be (`Some(false)`) or does not matter (`None`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Chord {
    key: &'static str,
    control: bool,
    shift: Option<bool>,
}

const fn key(key: &'static str) -> Chord {
    Chord {
        key,
        control: false,
        shift: None,
    }
}

const fn ctrl(key: &'static str, shift: bool) -> Chord {
    Chord {
        key,
        control: true,
        shift: Some(shift),
    }
}

/// One line of the help panel: where, the keys as shown, what they do, and the chords.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Binding {
    /// Where the keys act.
    pub scope: Scope,
    /// The keys, as the help panel and tooltips show them.
    pub keys: &'static str,
    /// What they do.
    pub what: &'static str,
    chords: &'static [(Chord, Command)],
}

const fn binding(
    scope: Scope,
    keys: &'static str,
    what: &'static str,
    chords: &'static [(Chord, Command)],
) -> Binding {
    Binding {
        scope,
        keys,
        what,
        chords,
    }
}

/// The arrow keys, for a focused view and the focused background region.
const ARROWS: &[(Chord, Command)] = &[
    (key("ArrowLeft"), Command::Left),
    (key("ArrowRight"), Command::Right),
    (key("ArrowUp"), Command::Up),
    (key("ArrowDown"), Command::Down),
];

/// + and - (with or without Shift, as keyboards place them).
const GROW_SHRINK: &[(Chord, Command)] = &[
    (key("+"), Command::Grow),
    (key("="), Command::Grow),
    (key("-"), Command::Shrink),
    (key("_"), Command::Shrink),
];

/// Every shortcut, in the help panel's order.
pub const KEYMAP: [Binding; 27] = [
    binding(
        Scope::Page,
        "R",
        "run H-Net",
        &[(key("r"), Command::RunModel)],
    ),
    binding(
        Scope::Page,
        "A",
        "use H-Net's masks as the labels",
        &[(key("a"), Command::AcceptMasks)],
    ),
    binding(Scope::Page, "B", "brush", &[(key("b"), Command::Brush)]),
    binding(Scope::Page, "E", "eraser", &[(key("e"), Command::Eraser)]),
    binding(
        Scope::Page,
        "H",
        "pan (or drag with the middle button)",
        &[(key("h"), Command::Pan)],
    ),
    binding(
        Scope::Page,
        "W",
        "window/level: drag on a DICOM frame (right: wider window, down: darker)",
        &[(key("w"), Command::WindowLevel)],
    ),
    binding(
        Scope::Page,
        "K",
        "play or pause the DICOM cine",
        &[(key("k"), Command::PlayPause)],
    ),
    binding(
        Scope::Page,
        ", / .",
        "previous / next cine frame",
        &[
            (key(","), Command::PreviousFrame),
            (key("."), Command::NextFrame),
        ],
    ),
    binding(
        Scope::Page,
        "[ / ]",
        "smaller / larger brush",
        &[
            (key("["), Command::SmallerBrush),
            (key("]"), Command::LargerBrush),
        ],
    ),
    binding(
        Scope::Page,
        "Ctrl+Z",
        "undo",
        &[(ctrl("z", false), Command::Undo)],
    ),
    binding(
        Scope::Page,
        "Ctrl+Shift+Z, Ctrl+Y",
        "redo",
        &[
            (ctrl("z", true), Command::Redo),
            (ctrl("y", false), Command::Redo),
            (ctrl("y", true), Command::Redo),
        ],
    ),
    binding(
        Scope::Page,
        "M",
        "show or hide H-Net's masks",
        &[(key("m"), Command::ToggleMasks)],
    ),
    binding(
        Scope::Page,
        "L",
        "show or hide the labels",
        &[(key("l"), Command::ToggleLabels)],
    ),
    binding(Scope::View, "Wheel", "zoom at the pointer", &[]),
    binding(
        Scope::Page,
        "0",
        "fit both views",
        &[(key("0"), Command::FitViews)],
    ),
    binding(
        Scope::Page,
        "N / P",
        "next / previous pair",
        &[
            (key("n"), Command::NextPair),
            (key("p"), Command::PreviousPair),
        ],
    ),
    binding(Scope::View, "← → ↑ ↓", "pan the focused view", ARROWS),
    binding(
        Scope::View,
        "+ / −",
        "zoom the focused view in / out",
        GROW_SHRINK,
    ),
    binding(
        Scope::Region,
        "← → ↑ ↓ (Shift: further)",
        "move the focused background region",
        ARROWS,
    ),
    binding(
        Scope::Region,
        "+ / −",
        "enlarge / shrink the focused background region",
        GROW_SHRINK,
    ),
    binding(
        Scope::Tabs,
        "← → ↑ ↓ Home End",
        "move between the source tabs (Images, DICOM cine, Digital twin, X-ray background); Enter \
         opens one",
        &[
            (key("ArrowLeft"), Command::Left),
            (key("ArrowUp"), Command::Left),
            (key("ArrowRight"), Command::Right),
            (key("ArrowDown"), Command::Right),
            (key("Home"), Command::First),
            (key("End"), Command::Last),
        ],
    ),
    binding(Scope::Scene, "Drag", "rotate the 3D view", &[]),
    binding(
        Scope::Scene,
        "← → ↑ ↓ (Shift: further)",
        "rotate the focused 3D view",
        ARROWS,
    ),
    binding(Scope::Scene, "Wheel", "zoom the 3D view", &[]),
    binding(
        Scope::Scene,
        "+ / −",
        "zoom the focused 3D view in / out",
        GROW_SHRINK,
    ),
    binding(
        Scope::Scene,
        "Home",
        "the 3D view's first angles and zoom",
        &[(key("Home"), Command::ResetView)],
    ),
    binding(
        Scope::Scene,
        "O",
        "perspective or orthographic 3D view",
        &[(key("o"), Command::ToggleProjection)],
    ),
];

/// The command of a key press in `scope` (`key` as `KeyboardEvent.key`; `control` for Ctrl or
/// ⌘), if any.
pub fn command(scope: Scope, key: &str, control: bool, shift: bool) -> Option<Command> {
    KEYMAP
        .iter()
        .filter(|b| b.scope == scope)
        .flat_map(|b| b.chords.iter())
        .find(|(chord, _)| {
            chord.key.eq_ignore_ascii_case(key)
                && chord.control == control
                && chord.shift.is_none_or(|s| s == shift)
        })
        .map(|(_, command)| *command)
}

/// `label` with the page-wide keys of `command` in parentheses, for a button's tooltip:
/// `tooltip("Run H-Net", Command::RunModel)` is `Run H-Net (R)`.
pub fn tooltip(label: &str, command: Command) -> String {
    match KEYMAP
        .iter()
        .find(|b| b.scope == Scope::Page && b.chords.iter().any(|(_, c)| *c == command))
    {
        Some(binding) => format!("{label} ({})", binding.keys),
        None => label.to_string(),
    }
}

/// The keys of `scope` and what they do, `keys: what` joined by `; `, for the tooltip and
/// description of the element they act on.
pub fn scope_help(scope: Scope) -> String {
    KEYMAP
        .iter()
        .filter(|b| b.scope == scope)
        .map(|b| format!("{}: {}", b.keys, b.what))
        .collect::<Vec<_>>()
        .join("; ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_find_their_command_in_their_scope_only() {
        // (scope, key, Ctrl, Shift): the command, if any.
        let cases = [
            ((Scope::Page, "R", false, false), Some(Command::RunModel)),
            ((Scope::Page, "z", true, false), Some(Command::Undo)),
            ((Scope::Page, "Z", true, true), Some(Command::Redo)),
            ((Scope::Page, "y", true, false), Some(Command::Redo)),
            // Ctrl with another key is the browser's (copy, paste, ...).
            ((Scope::Page, "c", true, false), None),
            ((Scope::Page, "ArrowLeft", false, false), None),
            (
                (Scope::View, "ArrowLeft", false, false),
                Some(Command::Left),
            ),
            ((Scope::Region, "+", false, true), Some(Command::Grow)),
            ((Scope::Tabs, "End", false, false), Some(Command::Last)),
            (
                (Scope::Scene, "O", false, false),
                Some(Command::ToggleProjection),
            ),
            ((Scope::Scene, "ArrowUp", false, true), Some(Command::Up)),
            ((Scope::Page, "Home", false, false), None),
        ];
        for ((scope, key, control, shift), expected) in cases {
            assert_eq!(
                command(scope, key, control, shift),
                expected,
                "{scope:?} {key} (Ctrl {control}, Shift {shift})"
            );
        }
    }

    #[test]
    fn the_3d_view_describes_its_keys_from_the_keymap() {
        let help = scope_help(Scope::Scene);
        assert!(
            help.starts_with("Drag: rotate the 3D view; ← → ↑ ↓ (Shift: further): rotate"),
            "{help}"
        );
        assert!(
            help.ends_with("O: perspective or orthographic 3D view"),
            "{help}"
        );
    }

    #[test]
    fn no_chord_means_two_things_in_one_scope() {
        let chords: Vec<(Scope, Chord)> = KEYMAP
            .iter()
            .flat_map(|b| b.chords.iter().map(move |(c, _)| (b.scope, *c)))
            .collect();
        for (i, a) in chords.iter().enumerate() {
            for b in &chords[i + 1..] {
                assert!(
                    !(a.0 == b.0
                        && a.1.key.eq_ignore_ascii_case(b.1.key)
                        && a.1.control == b.1.control
                        && (a.1.shift.is_none() || b.1.shift.is_none() || a.1.shift == b.1.shift)),
                    "{a:?} and {b:?} overlap"
                );
            }
        }
    }

    #[test]
    fn tooltips_show_the_keys_of_the_help_panel() {
        assert_eq!(tooltip("Run H-Net", Command::RunModel), "Run H-Net (R)");
        assert_eq!(tooltip("Undo", Command::Undo), "Undo (Ctrl+Z)");
        assert_eq!(
            tooltip("Redo", Command::Redo),
            "Redo (Ctrl+Shift+Z, Ctrl+Y)"
        );
        assert_eq!(tooltip("Fit", Command::FitViews), "Fit (0)");
    }
}
