import math

import pytest
from kinswarm.protocol.topology import TopologyError, load_topology


def test_chain4(chain4):
    t = load_topology(chain4)
    assert t.order == ("a1", "a2", "a3", "a4") and t.root == "a1"
    assert t.end_effectors == ("a4",)
    assert t.agents["a2"].parent == "a1" and t.agents["a1"].children == ("a2",)
    assert math.isclose(t.agents["a4"].initial, math.radians(30))
    assert t.reach == 12.0 and t.goal == (4.16, 6.18)


def test_tree(tree5):
    t = load_topology(tree5)
    assert t.agents["base"].children == ("l1", "r1")
    assert set(t.end_effectors) == {"l2", "r2"}
    assert t.subtree_leaves("base") == ("l2", "r2")
    assert t.subtree("base") == ("base", "l1", "l2", "r1", "r2") and t.subtree("r1") == ("r1", "r2")
    # links of 2; the branches' offsets turn (30 deg) but do not move their joints: no length of their own
    assert t.reach_below("base") == 6.0 and t.reach_below("l1") == 4.0 and t.reach_below("l2") == 2.0
    assert t.reach == 6.0


BASE = """
[[agent]]
id = "a1"
link_length = 1.0
[[agent]]
id = "a2"
parent = "a1"
link_length = 1.0
"""


@pytest.mark.parametrize(
    "text, field, what",
    [
        (BASE + '[[agent]]\nid = "a2"\nparent = "a1"\nlink_length = 1.0\n', "agent[2].id", "duplicate"),
        (BASE + '[[agent]]\nid = "b"\nlink_length = 1.0\n', "agent.parent", "exactly one root"),
        (BASE.replace('parent = "a1"', 'parent = "zz"'), "agent[1].parent", "unknown parent 'zz'"),
        (BASE.replace('id = "a2"', 'id = "a/2"'), "agent[1].id", "letters"),
        (BASE + "[robot]\nbase = [0, 0]\n", "robot.base", "list of 3"),
        (BASE.replace("link_length = 1.0\n[[agent]]", "link_length = -1.0\n[[agent]]"), "agent[0].link_length", "> 0"),
        (BASE + "limits_deg = [10, -10]\n", "agent[1].limits_deg", "below upper"),
        (BASE + "initial_deg = 500\n", "agent[1].initial_deg", "outside limits"),
        (BASE + 'colour = "red"\n', "agent[1].colour", "unknown field"),
        (BASE + '[[agent]]\nid = "c"\nparent = "a2"\ncompound = true\n', "agent[2].compound", "must have children"),
        (BASE + "[task]\ngoal = [1, 2, 3]\n", "task.goal", "list of 2"),
        (BASE + "[task]\ngoal = [1, nan]\n", "task.goal[1]", "finite"),
        (
            "[[agent]]\nid = 'a'\nlink_length = 1\n[[agent]]\nid = 'b'\nparent = 'c'\nlink_length = 1\n"
            "[[agent]]\nid = 'c'\nparent = 'b'\nlink_length = 1\n",
            "agent.parent",
            "not reachable",
        ),
        ("this is = = not toml", "toml", ""),
        ("[ghost]\n", "ghost", "unknown table"),
    ],
)
def test_errors_name_file_field_and_fault(tmp_path, text, field, what):
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises(TopologyError) as e:
        load_topology(p)
    assert str(p) in str(e.value)
    assert e.value.where == field
    assert what in e.value.what


def test_missing_file(tmp_path):
    with pytest.raises(TopologyError, match="cannot read"):
        load_topology(tmp_path / "nope.toml")
