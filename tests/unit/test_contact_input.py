"""Bad contact entries are bad input: one InputError naming the field (exit 2 from the CLI)."""

from __future__ import annotations

import pytest
import yaml

from cgfem.case import parse_case, parse_yaml
from cgfem.cli import main
from cgfem.errors import InputError

from tests.support.cases import PLANAR


def _with_contact(entries: list[dict]) -> dict:
    data = parse_yaml(PLANAR)
    data["contact"] = entries
    return data


@pytest.mark.parametrize("entries, field, words", [
    ([{"slave": "lower", "master": "nobody"}], "contact[0].master", "unknown body"),
    ([{"slave": "ghost", "master": "upper"}], "contact[0].slave", "unknown body"),
    ([{"slave": "lower", "master": "lower"}], "contact[0].master", "must differ"),
    ([{"slave": "lower", "master": "upper"}, {"slave": "upper", "master": "lower"}], "contact[1]",
     "already paired"),
    ([{"slave": "lower", "master": "upper", "slave_patches": ["zmax", "top"]}],
     "contact[0].slave_patches[1]", "unknown patch 'top'"),
    ([{"slave": "lower", "master": "upper", "master_patches": ["lid"]}],
     "contact[0].master_patches[0]", "unknown patch 'lid'"),
    ([{"slave": "lower", "master": "upper", "kappa": 0.0}], "contact[0].kappa", ""),
    ([{"slave": "lower", "master": "upper", "kappa": -3.0}], "contact[0].kappa", ""),
    ([{"slave": "lower", "master": "upper", "fit": "fine"}], "contact[0].fit", ""),
    ([{"slave": "lower", "master": "upper", "fit": -1}], "contact[0].fit", ""),
    ([{"slave": "lower", "master": "upper", "rule": "mortar"}], "contact[0].rule", ""),
])
def test_bad_contact_entries(tmp_path, entries, field, words):
    with pytest.raises(InputError) as err:
        parse_case(_with_contact(entries), tmp_path)
    assert err.value.field == field
    assert words in str(err.value)
    assert "\n" not in str(err.value)


def test_cli_exit_2_with_one_line(tmp_path, capsys):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(_with_contact([{"slave": "lower", "master": "lower"}])))
    code = main(["run", str(path), "--level", "0", "--surface", "nurbs_fe", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and "contact[0].master" in err[0]
    assert not (tmp_path / "out" / "summary.json").exists()


def test_patches_restrict_the_pair(tmp_path):
    case = parse_case(_with_contact([{"slave": "lower", "master": "upper", "slave_patches": ["zmax"],
                                      "master_patches": ["zmin"]}]), tmp_path)
    assert case.contact[0].slave_patches == ("zmax",)
    assert case.contact[0].master_patches == ("zmin",)
    assert parse_case(_with_contact([{"slave": "lower", "master": "upper"}]), tmp_path).contact[0].slave_patches is None


@pytest.mark.parametrize("fit", ["auto", "none", 0, 3])
def test_fit_option(tmp_path, fit):
    case = parse_case(_with_contact([{"slave": "lower", "master": "upper", "fit": fit}]), tmp_path)
    assert case.contact[0].fit == fit
    assert parse_case(_with_contact([{"slave": "lower", "master": "upper"}]), tmp_path).contact[0].fit == "auto"


def test_segmented_rule_with_facets_is_refused(tmp_path, capsys):
    """``rule: segmented`` splits exact NURBS patches: with ``--surface facets`` exit 2, one
    line naming the field, before any body is built (no output folder)."""
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(_with_contact([{"slave": "lower", "master": "upper", "rule": "segmented"}])))
    code = main(["run", str(path), "--level", "0", "--surface", "facets", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and "contact[0].rule" in err[0] and "facets" in err[0]
    assert not (tmp_path / "out").exists()
