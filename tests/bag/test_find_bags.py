"""hd_bag.files.find_bags: the one bag finder, with each caller's rules (order, repeats, errors)."""

import pytest

from hd_bag.files import find_bags


@pytest.fixture
def tree(tmp_path):
    for rel in ("a/b.mcap", "a/a.mcap", "a-b/c.mcap", "a/sub/z.mcap", "top.mcap"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_bytes(b"")
    (tmp_path / "a" / "dir.mcap").mkdir()  # a ros2 bag folder named like a file
    (tmp_path / "empty").mkdir()
    return tmp_path


def test_order_repeats_and_files_only(tree):
    rel = lambda ps: [str(p.relative_to(tree)) for p in ps]  # noqa: E731
    assert rel(find_bags([tree / "a", tree / "top.mcap"], files_only=True)) == [
        "a/a.mcap", "a/b.mcap", "a/sub/z.mcap", "top.mcap"]
    assert "a/dir.mcap" in rel(find_bags([tree / "a"]))
    # path order ("a" < "a-b" part by part) against text order ("a-b/" < "a/")
    assert rel(find_bags([tree], files_only=True))[:2] == ["a/a.mcap", "a/b.mcap"]
    assert rel(find_bags([tree], files_only=True, sort_key=str))[0] == "a-b/c.mcap"
    twice = [tree / "top.mcap", tree / "a" / "a.mcap", tree / "top.mcap"]
    assert rel(find_bags(twice)) == ["top.mcap", "a/a.mcap", "top.mcap"]
    assert rel(find_bags(twice, unique="first")) == ["top.mcap", "a/a.mcap"]
    assert rel(find_bags(twice, unique="sorted")) == ["a/a.mcap", "top.mcap"]
    assert rel(find_bags([str(tree / "a" / "*.mcap")], patterns=True, files_only=True)) == [
        "a/a.mcap", "a/b.mcap"]  # a pattern's hits: files taken, directories (dir.mcap, empty) searched


def test_errors_name_the_path(tree):
    with pytest.raises(FileNotFoundError, match="nope: no such bag file or directory"):
        find_bags([tree / "nope"], error=FileNotFoundError)
    with pytest.raises(ValueError, match="empty: directory holds no .mcap bag"):
        find_bags([tree / "empty"], empty_dir_error=True)
    with pytest.raises(ValueError, match="no .mcap bags under .*empty"):
        find_bags([tree / "empty"])
    assert find_bags([tree / "empty"], empty_error=False) == []
    with pytest.raises(ValueError, match=r"\*.zzz: no file matches"):
        find_bags([str(tree / "*.zzz")], patterns=True)


def test_read_json_names_the_path(tmp_path):
    from hd_bag.files import read_json

    (tmp_path / "ok.json").write_text('{"a": 1}')
    assert read_json(tmp_path / "ok.json", "a thing") == {"a": 1}
    with pytest.raises(FileNotFoundError, match="gone.json: a thing not found"):
        read_json(tmp_path / "gone.json", "a thing")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(ValueError, match="bad.json: a thing is not valid JSON"):
        read_json(tmp_path / "bad.json", "a thing")
    with pytest.raises(ValueError, match=r"ok.json: 8 bytes is larger than the 4-byte cap"):
        read_json(tmp_path / "ok.json", "a thing", max_bytes=4)
