"""Paraphrase templates for the synthetic clips, and the tagging of Inter-X ``texts_processed``.

Each clip gets three captions from three different templates of its interaction. Slots:
``{A}`` the actor and ``{B}`` the other person (consistent pairs such as "one person" / "the
other", "the first person" / "the second person" matching who really acts), ``{adv}`` a speed
adverb matching the sampled speed (empty at normal speed), ``{side}`` the acting hand or leg, and
``{their}`` the actor's possessive.

Single-person captions (``SOLO_TEMPLATES``, for the HumanML3D layout) describe what the actor
alone does, with ``{A}`` a single-person phrase; the partner is at most "someone".

Inter-X and HumanML3D store captions as ``caption#tok/POS tok/POS ...#0.0#0.0`` with lower-case lemmas and
universal POS tags (HumanML3D style). The vocabulary of the templates is closed, so a small
lexicon tags it exactly; a word missing from it is a bug in the templates and raises.
"""

from __future__ import annotations

import re

import numpy as np

FAST_SPEED, SLOW_SPEED = 1.2, 0.85  # speed factors beyond which captions say "quickly"/"slowly"
FAST_WORDS = ("quickly", "rapidly", "briskly")
SLOW_WORDS = ("slowly", "gently", "calmly")
CAPTIONS_PER_CLIP = 3

TEMPLATES: dict[str, tuple[str, ...]] = {
    "handshake": (
        "{A} {adv}reaches out {their} {side} hand and {B} shakes it.",
        "{A} {adv}extends {their} {side} hand to {B}, who takes it and shakes hands.",
        "{A} {adv}offers a handshake with {their} {side} hand, and {B} accepts.",
        "{A} {adv}holds out {their} {side} hand first and the two shake hands.",
    ),
    "hug": (
        "{A} {adv}steps toward {B} and hugs them, and {B} hugs back.",
        "{A} {adv}walks up to {B} and embraces them; {B} returns the hug.",
        "{A} {adv}wraps both arms around {B}, who hugs back.",
        "{A} {adv}approaches {B} for a hug and the two embrace.",
    ),
    "push": (
        "{A} {adv}pushes {B} with both hands, and {B} stumbles backward.",
        "{A} {adv}shoves {B} in the chest, making {B} stagger back a few steps.",
        "{A} {adv}pushes {B} away and {B} staggers backward.",
        "with both hands, {A} {adv}pushes {B}, who stumbles back.",
    ),
    "punch_dodge": (
        "{A} {adv}throws a punch at {B} with {their} {side} fist, and {B} dodges it.",
        "{A} {adv}punches toward the head of {B} with {their} {side} hand, but {B} leans back to avoid it.",
        "{A} {adv}swings {their} {side} fist at {B}, who dodges backward.",
        "{A} {adv}tries to punch {B} with {their} {side} hand and {B} evades the blow.",
    ),
    "wave": (
        "{A} {adv}waves {their} {side} hand at {B}, and {B} waves back.",
        "{A} raises {their} {side} hand and {adv}waves to {B}, who waves back.",
        "{A} {adv}greets {B} with a wave of {their} {side} hand, and {B} returns the wave.",
        "{A} {adv}waves hello with {their} {side} hand and {B} answers with a wave.",
    ),
    "bow": (
        "{A} {adv}bows to {B}, and {B} bows in return.",
        "{A} {adv}bends forward in a bow, and {B} bows back.",
        "the two bow to each other after {A} {adv}bows first.",
        "{A} {adv}bows politely to {B}, who returns the bow.",
    ),
    "walk_meet": (
        "{A} {adv}walks toward {B}, and {B} walks over to meet them.",
        "{A} {adv}sets off first and the two walk toward each other until they meet.",
        "{A} {adv}approaches {B}, who also walks forward until they meet.",
        "{A} {adv}walks up to {B} while {B} comes closer, and they stop face to face.",
    ),
    "dance": (
        "{A} {adv}starts to dance and {B} joins in, dancing in sync.",
        "{A} {adv}dances in front of {B}, and {B} joins and dances along in sync.",
        "the two dance together in sync after {A} {adv}starts first.",
        "{A} {adv}begins to bounce and sway to the beat, and {B} dances along.",
    ),
    "pass_object": (
        "{A} {adv}hands an object to {B} with {their} {side} hand, and {B} takes it.",
        "{A} {adv}holds out something in {their} {side} hand and {B} reaches out to take it.",
        "{A} {adv}passes an item to {B} with {their} {side} hand.",
        "{A} {adv}gives {B} an object using {their} {side} hand, and {B} receives it.",
    ),
    "high_five": (
        "{A} {adv}raises {their} {side} hand and {B} gives them a high five.",
        "{A} {adv}lifts {their} {side} hand first and the two give each other a high five.",
        "{A} {adv}holds up {their} {side} hand for a high five and {B} slaps it.",
        "{A} {adv}offers a high five with {their} {side} hand, and {B} claps it.",
    ),
    "kick_block": (
        "{A} {adv}kicks at {B} with {their} {side} leg, and {B} blocks the kick with both arms.",
        "{A} {adv}throws a kick with {their} {side} leg toward {B}, who guards with both arms.",
        "{A} {adv}kicks {B} with {their} {side} foot while {B} blocks and steps back.",
        "{A} {adv}lifts {their} {side} leg to kick {B}, and {B} defends with crossed arms.",
    ),
    "chase": (
        "{A} {adv}runs after {B}, who turns around and runs away.",
        "{A} {adv}chases {B}; {B} turns and flees.",
        "{A} {adv}runs toward {B}, and {B} turns away and runs off.",
        "{A} {adv}starts chasing {B}, who spins around and escapes.",
    ),
    "pat_shoulder": (
        "{A} {adv}pats {B} on the shoulder with {their} {side} hand, and {B} pats back.",
        "{A} {adv}taps the shoulder of {B} with {their} {side} hand, and {B} does the same.",
        "{A} {adv}puts {their} {side} hand on the shoulder of {B} and pats it; {B} returns the gesture.",
        "{A} {adv}pats {B} on the shoulder, and {B} answers with a pat.",
    ),
    "beckon": (
        "{A} {adv}beckons {B} with {their} {side} hand, and {B} walks over.",
        "{A} {adv}gestures with {their} {side} hand for {B} to come, and {B} approaches.",
        "{A} {adv}calls {B} over with {their} {side} hand, and {B} walks toward them.",
        "{A} {adv}beckons with {their} {side} hand, and {B} walks up to them.",
    ),
}

SOLO_TEMPLATES: dict[str, tuple[str, ...]] = {
    "handshake": (
        "{A} {adv}reaches out {their} {side} hand and shakes hands.",
        "{A} {adv}extends {their} {side} hand for a handshake.",
        "{A} {adv}holds out {their} {side} hand to shake hands with someone.",
    ),
    "hug": (
        "{A} {adv}steps forward and hugs someone.",
        "{A} {adv}walks up to someone and wraps both arms around them.",
        "{A} {adv}approaches and embraces someone with both arms.",
    ),
    "push": (
        "{A} {adv}pushes forward with both hands.",
        "{A} {adv}shoves someone in the chest with both hands.",
        "with both hands, {A} {adv}pushes someone away.",
    ),
    "punch_dodge": (
        "{A} {adv}throws a punch with {their} {side} fist.",
        "{A} {adv}punches forward with {their} {side} hand.",
        "{A} {adv}swings {their} {side} fist at someone.",
    ),
    "wave": (
        "{A} {adv}waves {their} {side} hand.",
        "{A} raises {their} {side} hand and {adv}waves.",
        "{A} {adv}waves hello with {their} {side} hand.",
    ),
    "bow": (
        "{A} {adv}bows forward.",
        "{A} {adv}bends forward in a bow.",
        "{A} {adv}bows politely.",
    ),
    "walk_meet": (
        "{A} {adv}walks forward and stops.",
        "{A} {adv}sets off and walks forward until they stop.",
        "{A} {adv}walks forward a few steps and stops.",
    ),
    "dance": (
        "{A} {adv}starts to dance.",
        "{A} {adv}bounces and sways to the beat.",
        "{A} {adv}begins to dance to the beat.",
    ),
    "pass_object": (
        "{A} {adv}hands an object forward with {their} {side} hand.",
        "{A} {adv}holds out something in {their} {side} hand.",
        "{A} {adv}passes an item to someone with {their} {side} hand.",
    ),
    "high_five": (
        "{A} {adv}raises {their} {side} hand for a high five.",
        "{A} {adv}lifts {their} {side} hand and gives a high five.",
        "{A} {adv}holds up {their} {side} hand for a high five.",
    ),
    "kick_block": (
        "{A} {adv}kicks with {their} {side} leg.",
        "{A} {adv}throws a kick with {their} {side} leg.",
        "{A} {adv}lifts {their} {side} leg to kick.",
    ),
    "chase": (
        "{A} {adv}runs forward.",
        "{A} {adv}runs after someone.",
        "{A} {adv}starts chasing someone.",
    ),
    "pat_shoulder": (
        "{A} {adv}pats someone on the shoulder with {their} {side} hand.",
        "{A} {adv}taps the shoulder of someone with {their} {side} hand.",
        "{A} {adv}reaches out {their} {side} hand and pats a shoulder.",
    ),
    "beckon": (
        "{A} {adv}beckons with {their} {side} hand.",
        "{A} {adv}gestures with {their} {side} hand for someone to come.",
        "{A} {adv}calls someone over with {their} {side} hand.",
    ),
}
SOLO_PHRASES = ("a person", "the person")
# A time-tagged sub-clip where the person moves across the floor: (minimum speed m/s, caption).
MOVING_CAPTIONS = ((2.0, "{A} runs forward."), (0.0, "{A} walks forward."))

# (actor, other) phrasings; "first"/"second" must name the person who really acts.
_NEUTRAL_PAIRS = (
    ("one person", "the other person"),
    ("one person", "the other"),
    ("a person", "another person"),
    ("someone", "another person"),
)
_ORDINAL_PAIRS = {
    1: ("the first person", "the second person"),
    2: ("the second person", "the first person"),
}


def speed_adverbs(speed: float) -> tuple[str, ...]:
    """Adverbs a caption may use for a clip played at `speed` (empty at normal speed)."""
    if speed > FAST_SPEED:
        return FAST_WORDS
    if speed < SLOW_SPEED:
        return SLOW_WORDS
    return ()


def _fill(template: str, *, actor: str, other: str, adverb: str, side: str) -> str:
    text = template.format(
        A=actor, B=other, adv=f"{adverb} " if adverb else "", side=side, their="their"
    )
    return text[0].upper() + text[1:]


def make_captions(
    rng: np.random.Generator, *, action: str, actor: int, side: str, speed: float
) -> tuple[str, ...]:
    """Three captions from three distinct templates of `action` (actor is person 1 or 2)."""
    templates = TEMPLATES[action]
    chosen = rng.choice(len(templates), size=CAPTIONS_PER_CLIP, replace=False)
    pairs = (*_NEUTRAL_PAIRS, _ORDINAL_PAIRS[actor])
    adverbs = speed_adverbs(speed)
    captions = []
    for index in chosen:
        actor_phrase, other_phrase = pairs[int(rng.integers(len(pairs)))]
        adverb = adverbs[int(rng.integers(len(adverbs)))] if adverbs else ""
        captions.append(
            _fill(
                templates[int(index)],
                actor=actor_phrase,
                other=other_phrase,
                adverb=adverb,
                side=side,
            )
        )
    return tuple(captions)


def make_solo_captions(
    rng: np.random.Generator, *, action: str, side: str, speed: float
) -> tuple[str, ...]:
    """The single-person templates of `action`, in a random order, each with a random phrase for
    the person and an adverb matching `speed`."""
    templates = SOLO_TEMPLATES[action]
    adverbs = speed_adverbs(speed)
    captions = []
    for index in rng.permutation(len(templates)):
        phrase = SOLO_PHRASES[int(rng.integers(len(SOLO_PHRASES)))]
        adverb = adverbs[int(rng.integers(len(adverbs)))] if adverbs else ""
        captions.append(
            _fill(templates[int(index)], actor=phrase, other="", adverb=adverb, side=side)
        )
    return tuple(captions)


def moving_caption(rng: np.random.Generator, speed: float) -> str:
    """Caption of a sub-clip in which the person moves at `speed` m/s on average."""
    template = next(text for floor, text in MOVING_CAPTIONS if speed >= floor)
    phrase = SOLO_PHRASES[int(rng.integers(len(SOLO_PHRASES)))]
    return _fill(template, actor=phrase, other="", adverb="", side="")


# ----------------------------------------------------------------------------- POS tagging

_TAGS: dict[
    str, tuple[str, ...]
] = {  # universal POS -> words that are their own lemma; first tag wins
    "DET": ("a", "an", "the", "another", "both", "each", "their"),
    "NOUN": (
        "person",
        "hand",
        "handshake",
        "hug",
        "chest",
        "step",
        "punch",
        "fist",
        "head",
        "blow",
        "wave",
        "hello",
        "bow",
        "face",
        "beat",
        "object",
        "item",
        "five",
        "kick",
        "leg",
        "foot",
        "arm",
        "shoulder",
        "pat",
        "gesture",
        "return",
        "sync",
        "front",
    ),
    "PRON": ("someone", "it", "they", "them", "who", "something", "other", "one", "two", "same"),
    "ADJ": ("left", "right", "first", "second", "high", "few", "crossed"),
    "ADV": (
        "back",
        "backward",
        "away",
        "forward",
        "over",
        "along",
        "closer",
        "also",
        "together",
        "quickly",
        "rapidly",
        "briskly",
        "slowly",
        "gently",
        "calmly",
        "politely",
        "around",
        "off",
        "out",
        "up",
    ),
    "ADP": ("to", "with", "at", "toward", "in", "of", "for", "on", "after"),
    "CCONJ": ("and", "but"),
    "SCONJ": ("while", "until"),
}
_VERBS = (  # base forms; the third person singular is derived
    "reach",
    "shake",
    "extend",
    "take",
    "offer",
    "accept",
    "hold",
    "step",
    "hug",
    "walk",
    "embrace",
    "return",
    "wrap",
    "approach",
    "push",
    "stumble",
    "shove",
    "stagger",
    "throw",
    "dodge",
    "punch",
    "lean",
    "avoid",
    "swing",
    "try",
    "evade",
    "wave",
    "raise",
    "greet",
    "answer",
    "bow",
    "bend",
    "meet",
    "start",
    "come",
    "stop",
    "dance",
    "join",
    "begin",
    "bounce",
    "sway",
    "hand",
    "pass",
    "give",
    "receive",
    "lift",
    "slap",
    "clap",
    "kick",
    "guard",
    "block",
    "defend",
    "run",
    "turn",
    "chase",
    "flee",
    "spin",
    "escape",
    "pat",
    "tap",
    "put",
    "do",
    "beckon",
    "gesture",
    "call",
    "set",
)
_PARTICIPLES = {
    "holding": "hold",
    "making": "make",
    "bowing": "bow",
    "starting": "start",
    "dancing": "dance",
    "lifting": "lift",
    "chasing": "chase",
    "using": "use",
}
_PLURAL_NOUNS = {"hands": "hand", "arms": "arm", "steps": "step"}
# A word that can be a noun or a verb is a noun after these words ("a wave", "both hands").
_NOUN_CONTEXT = frozenset(
    {
        "a",
        "an",
        "the",
        "their",
        "both",
        "crossed",
        "left",
        "right",
        "high",
        "few",
        "shake",
        "shakes",
    }
)
# ... and a verb after the infinitive "to" ("to kick", "to take").
_VERB_CONTEXT = frozenset({"to"})


_WORD = re.compile(r"[a-z]+")


def _third_person(verb: str) -> str:
    if verb.endswith("y") and verb[-2] not in "aeiou":
        return verb[:-1] + "ies"
    return verb + ("es" if verb.endswith(("sh", "ch", "ss", "x", "o")) else "s")


def _build_lexicon() -> dict[str, tuple[str, str]]:
    lexicon: dict[str, tuple[str, str]] = {}
    for tag, words in _TAGS.items():
        for word in words:
            lexicon.setdefault(word, (word, tag))
    for verb in _VERBS:
        lexicon.setdefault(verb, (verb, "VERB"))
        lexicon.setdefault(_third_person(verb), (verb, "VERB"))
    for form, lemma in _PARTICIPLES.items():
        lexicon.setdefault(form, (lemma, "VERB"))
    for (
        form,
        lemma,
    ) in _PLURAL_NOUNS.items():  # "hands", "steps" stay verbs unless the context says noun
        lexicon.setdefault(form, (lemma, "NOUN"))
    return lexicon


LEXICON: dict[str, tuple[str, str]] = _build_lexicon()  # word -> (lemma, universal POS)
_VERB_BASES = frozenset(_VERBS)


def _tag_word(word: str, previous: str) -> tuple[str, str]:
    if word not in LEXICON:
        raise KeyError(word)
    lemma, tag = LEXICON[word]
    if previous in _NOUN_CONTEXT and (
        word in _PLURAL_NOUNS or (tag == "VERB" and lemma in _TAGS["NOUN"])
    ):
        return _PLURAL_NOUNS.get(word, lemma), "NOUN"
    if previous in _VERB_CONTEXT and word in _VERB_BASES:
        return word, "VERB"
    return lemma, tag


def tag_caption(caption: str) -> str:
    """'caption' -> 'lemma/POS lemma/POS ...' (lower case, punctuation dropped).

    Raises ValueError naming the word when the caption leaves the templates' vocabulary.
    """
    words = _WORD.findall(caption.lower())
    tokens, previous = [], ""
    for word in words:
        try:
            lemma, tag = _tag_word(word, previous)
        except KeyError:
            raise ValueError(
                f"word {word!r} of caption {caption!r} is missing from the synthetic lexicon"
            ) from None
        if tag == "VERB" and previous in _VERB_CONTEXT:
            tokens[-1] = f"{previous}/PART"  # the infinitive marker, not a preposition
        tokens.append(f"{lemma}/{tag}")
        previous = word
    return " ".join(tokens)


def processed_line(caption: str, start: str = "0.0", end: str = "0.0") -> str:
    """One Inter-X texts_processed / HumanML3D texts line: caption#tagged tokens#start#end (the
    time tags in seconds, 0.0#0.0 for the whole clip)."""
    return f"{caption}#{tag_caption(caption)}#{start}#{end}"
