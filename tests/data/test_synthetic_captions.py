"""Captions of the synthetic clips: distinct paraphrases consistent with the motion."""

from __future__ import annotations

import itertools
import re

import numpy as np
import pytest

from intermask.data.synthetic import ACTIONS, generate_clip
from intermask.data.synthetic.captions import (
    FAST_WORDS,
    SLOW_WORDS,
    TEMPLATES,
    _fill,
    make_captions,
    processed_line,
    speed_adverbs,
    tag_caption,
)

ONE_HANDED = (
    "handshake",
    "punch_dodge",
    "wave",
    "pass_object",
    "high_five",
    "kick_block",
    "pat_shoulder",
    "beckon",
)


def test_every_interaction_has_enough_templates() -> None:
    assert set(TEMPLATES) == set(ACTIONS)
    assert all(len(set(templates)) >= 4 for templates in TEMPLATES.values())


def test_three_distinct_captions_naming_the_right_people() -> None:
    rng = np.random.default_rng(0)
    for action in ACTIONS:
        for actor in (1, 2):
            captions = make_captions(rng, action=action, actor=actor, side="left", speed=1.0)
            assert len(captions) == 3 and len(set(captions)) == 3
            for caption in captions:
                assert caption[0].isupper() and caption.endswith(".")
                lower = caption.lower()
                if "the first person" in lower or "the second person" in lower:
                    actor_word = "the first person" if actor == 1 else "the second person"
                    assert lower.startswith(actor_word) or f"after {actor_word}" in lower, caption


@pytest.mark.parametrize(
    "speed, words, absent", [(1.35, FAST_WORDS, SLOW_WORDS), (0.75, SLOW_WORDS, FAST_WORDS)]
)
def test_speed_words_match_the_speed(
    speed: float, words: tuple[str, ...], absent: tuple[str, ...]
) -> None:
    rng = np.random.default_rng(1)
    for action in ACTIONS:
        for caption in make_captions(rng, action=action, actor=1, side="right", speed=speed):
            tokens = set(re.findall(r"[a-z]+", caption.lower()))
            assert tokens & set(words) and not tokens & set(absent), caption
    assert speed_adverbs(1.0) == ()


def test_clip_captions_follow_the_sampled_side_and_speed() -> None:
    for index, action in enumerate(ONE_HANDED * 2):
        clip = generate_clip(seed=5, index=index, action=action)
        other = "left" if clip.side == "right" else "right"
        words = [set(re.findall(r"[a-z]+", c.lower())) for c in clip.captions]
        assert all(other not in w for w in words), clip.captions
        assert any(clip.side in w for w in words), clip.captions
        speed_words = set(speed_adverbs(clip.speed))
        assert all(bool(w & speed_words) == bool(speed_words) for w in words), (
            clip.speed,
            clip.captions,
        )


def test_every_template_word_is_tagged() -> None:
    pairs = [("one person", "the other"), ("the second person", "the first person")]
    for templates in TEMPLATES.values():
        for template, (actor, other), adverb in itertools.product(
            templates, pairs, ("", *FAST_WORDS, *SLOW_WORDS)
        ):
            tag_caption(_fill(template, actor=actor, other=other, adverb=adverb, side="left"))
    with pytest.raises(ValueError, match="'zebra' .* missing from the synthetic lexicon"):
        tag_caption("A zebra waves.")


def test_processed_line_format_and_tags() -> None:
    line = processed_line(
        "One person quickly waves their left hand at the other, and the other waves back."
    )
    caption, tokens, start, end = line.split("#")
    assert caption.startswith("One person quickly waves") and (start, end) == ("0.0", "0.0")
    assert tokens.split() == [
        "one/PRON",
        "person/NOUN",
        "quickly/ADV",
        "wave/VERB",
        "their/DET",
        "left/ADJ",
        "hand/NOUN",
        "at/ADP",
        "the/DET",
        "other/PRON",
        "and/CCONJ",
        "the/DET",
        "other/PRON",
        "wave/VERB",
        "back/ADV",
    ]
    assert "to/PART take/VERB" in tag_caption("The other reaches out to take it.")
    assert "a/DET wave/NOUN" in tag_caption("The other answers with a wave.")
