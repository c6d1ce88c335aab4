import pytest

from intermask.data.captions import swap_left_right


@pytest.mark.parametrize(
    ("caption", "expected"),
    [
        ("One person turns left.", "One person turns right."),
        ("Right, then LEFT!", "Left, then RIGHT!"),
        ("they spin counterclockwise", "they spin clockwise"),
        ("they spin clockwise", "they spin counterclockwise"),
        ("Clockwise first, counterclockwise after", "Counterclockwise first, clockwise after"),
        (
            "anticlockwise and anti-clockwise and counter-clockwise",
            "clockwise and clockwise and clockwise",
        ),
        ("his left-hand grabs the other's right arm", "his right-hand grabs the other's left arm"),
        ("moves leftward, then rightwards", "moves rightward, then leftwards"),
        ("a bright leftover outright", "a bright leftover outright"),
        ("", ""),
    ],
)
def test_swap_left_right_by_words(caption, expected):
    assert swap_left_right(caption) == expected


def test_counterclockwise_never_doubles():
    # The reference's chained substring replacement produces "countercounterclockwise".
    out = swap_left_right("turn clockwise then counterclockwise")
    assert "countercounter" not in out
    assert out == "turn counterclockwise then clockwise"


def test_swap_twice_is_identity_for_canonical_spellings():
    caption = "The left one walks right, turning Clockwise; the RIGHT one counterclockwise."
    assert swap_left_right(swap_left_right(caption)) == caption
