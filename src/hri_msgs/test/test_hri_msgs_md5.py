"""The generated hri_msgs/IdsList must be byte-compatible with REP 155 trackers built on hri_msgs 0.9.0: the same MD5
sum (a mismatch drops the connection at subscription time)."""

import pytest
from hri_msgs.msg import IdsList

pytestmark = pytest.mark.core

# hri_msgs 0.9.0's IdsList, as its generated code (C++, JavaScript, C#) spells it.
UPSTREAM_MD5 = "84a63f55b5676f78b625e8a8bb809fe5"


def test_md5_equals_hri_msgs_0_9():
    assert IdsList._type == "hri_msgs/IdsList"
    assert IdsList._md5sum == UPSTREAM_MD5
    assert IdsList.__slots__ == ["header", "ids"]
