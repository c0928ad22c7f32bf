import math

import pytest
from kinswarm.protocol.robots import load_robot
from kinswarm.protocol.spec import SpecError


def test_chain4(chain4):
    t = load_robot(chain4)
    assert t.order == ("a1", "a2", "a3", "a4") and t.root == "a1"
    assert t.end_effectors == ("a4",)
    assert t.agents["a2"].parent == "a1" and t.agents["a1"].children == ("a2",)
    assert math.isclose(t.agents["a4"].initial, math.radians(30))
    assert t.reach == 12.0 and t.name == "chain4"


def test_tree(tree5):
    t = load_robot(tree5)
    assert t.agents["base"].children == ("l1", "r1")
    assert set(t.end_effectors) == {"l2", "r2"}
    assert t.subtree_leaves("base") == ("l2", "r2")
    assert t.subtree("base") == ("base", "l1", "l2", "r1", "r2") and t.subtree("r1") == ("r1", "r2")
    # links of 2; the branches' offsets turn (30 deg) but do not move their joints: no length of their own
    assert t.reach_below("base") == 6.0 and t.reach_below("l1") == 4.0 and t.reach_below("l2") == 2.0
    assert t.reach == 6.0


BASE = """
[robot]
[[robot.agent]]
id = "a1"
link_length = 1.0
[[robot.agent]]
id = "a2"
parent = "a1"
link_length = 1.0
"""
A2 = '[[robot.agent]]\nid = "a2"\nparent = "a1"\nlink_length = 1.0\n'


@pytest.mark.parametrize(
    "text, field, what",
    [
        (BASE + A2, "robot.agent[2].id", "duplicate"),
        (BASE + '[[robot.agent]]\nid = "b"\nlink_length = 1.0\n', "robot.agent.parent", "exactly one root"),
        (BASE.replace('parent = "a1"', 'parent = "zz"'), "robot.agent[1].parent", "unknown parent 'zz'"),
        (BASE.replace('id = "a2"', 'id = "a/2"'), "robot.agent[1].id", "letters"),
        (BASE.replace("[robot]\n", "[robot]\nbase = [0, 0]\n"), "robot.base", "list of 3"),
        (
            BASE.replace("link_length = 1.0\n[[robot", "link_length = -1.0\n[[robot", 1),
            "robot.agent[0].link_length",
            "> 0",
        ),
        (BASE + "limits_deg = [10, -10]\n", "robot.agent[1].limits_deg", "below upper"),
        (BASE + "initial_deg = 500\n", "robot.agent[1].initial_deg", "outside limits"),
        (BASE + 'colour = "red"\n', "robot.agent[1].colour", "unknown field"),
        (BASE + '[[robot.agent]]\nid = "c"\nparent = "a2"\ncompound = true\n', "robot.agent[2].compound", "children"),
        (BASE + "[robot.defaults]\nlink = 2\n", "robot.defaults.link", "unknown field"),
        (
            "[robot]\n[[robot.agent]]\nid = 'a'\nlink_length = 1\n[[robot.agent]]\nid = 'b'\nparent = 'c'\n"
            "link_length = 1\n[[robot.agent]]\nid = 'c'\nparent = 'b'\nlink_length = 1\n",
            "robot.agent.parent",
            "not reachable",
        ),
        ("this is = = not toml", "toml", ""),
        ("[ghost]\n", "robot", "[robot] table"),
    ],
)
def test_errors_name_file_field_and_fault(tmp_path, text, field, what):
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises(SpecError) as e:
        load_robot(p)
    assert str(p) in str(e.value)
    assert e.value.where == field
    assert what in e.value.what


def test_missing_file(tmp_path):
    with pytest.raises(SpecError, match="cannot read"):
        load_robot(tmp_path / "nope.toml")
