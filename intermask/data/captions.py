"""Caption edits that accompany motion augmentation."""

from __future__ import annotations

import re

# Each entry maps a lower-case word to its mirror image. Matching is by whole words, so
# "counterclockwise" is one word and never becomes "countercounterclockwise" (the reference
# InterGen/InterMask loaders chain substring replacements and produce exactly that).
_MIRROR_WORDS: dict[str, str] = {
    "left": "right",
    "right": "left",
    "lefts": "rights",
    "rights": "lefts",
    "leftward": "rightward",
    "rightward": "leftward",
    "leftwards": "rightwards",
    "rightwards": "leftwards",
    "lefthand": "righthand",
    "righthand": "lefthand",
    "leftmost": "rightmost",
    "rightmost": "leftmost",
    "clockwise": "counterclockwise",
    "counterclockwise": "clockwise",
    "counter-clockwise": "clockwise",
    "anticlockwise": "clockwise",
    "anti-clockwise": "clockwise",
}

# Longest alternatives first so that "counter-clockwise" wins over its suffix "clockwise".
_PATTERN = re.compile(
    r"\b(" + "|".join(re.escape(w) for w in sorted(_MIRROR_WORDS, key=len, reverse=True)) + r")\b",
    flags=re.IGNORECASE,
)


def _match_case(template: str, word: str) -> str:
    if template.isupper() and len(template) > 1:
        return word.upper()
    if template[0].isupper():
        return word[0].upper() + word[1:]
    return word


def swap_left_right(caption: str) -> str:
    """Swap left/right and clockwise/counterclockwise words, as a mirror image of the motion.

    Whole words only ("bright" and "leftover" stay), case is kept ("Left" -> "Right",
    "LEFT" -> "RIGHT"), punctuation and spacing are untouched. "anticlockwise" and the hyphenated
    spellings map to "clockwise". Applying it twice restores the caption except for those
    synonym spellings.
    """
    return _PATTERN.sub(
        lambda m: _match_case(m.group(0), _MIRROR_WORDS[m.group(0).lower()]), caption
    )
