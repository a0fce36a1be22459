"""What the reset says when no camera sees the robot's reach (moverl_gym.sensed, issue 52): the share of the reach,
where it lies and the tool that shows what the cameras see; nothing when the census tells nothing."""

import pytest

from moverl_gym.sensed import CAMERAS_TOOL, SensedCensus, describe_unseen

pytestmark = pytest.mark.core


def _census(unseen=0, stale=0, free=1000, octants=None, unknown_occupied=True):
    cells = unseen + stale + free
    return SensedCensus(
        cells_by_octant=(cells // 8,) * 8,
        radius=1.32,
        cells=cells,
        free=free,
        seen_occupied=0,
        stale=stale,
        unseen=unseen,
        unknown_occupied=unknown_occupied,
        hidden_by_octant=tuple(octants or [0] * 8),
    )


def test_it_says_how_much_of_the_reach_is_unseen_where_and_with_which_tool():
    # 125 cells per octant; 600 hidden: every cell below the base (octants 0-3), 50 behind-right above (4) and 50
    # behind-left above (6).
    text = describe_unseen(_census(unseen=500, stale=100, free=400, octants=[125] * 4 + [50, 0, 50, 0]), "cell")
    assert text.startswith("60 % of the robot's reach (the 1.32 m ball around its base) is space no camera sees")
    assert "50 % never seen, 10 % hidden since it was seen free" in text
    assert "20 % above its base (in front-left 0 %, in front-right 0 %, behind-left 40 %, behind-right 40 %)" in text
    assert "100 % below it" in text
    assert "world 'cell'" in text and CAMERAS_TOOL in text and "Placing your cameras" in text


def test_it_says_nothing_without_a_map_without_unseen_space_or_when_unseen_space_is_free():
    assert describe_unseen(None, "cell") == ""
    assert describe_unseen(_census(), "cell") == ""
    assert describe_unseen(_census(unseen=500, unknown_occupied=False), "cell") == ""
