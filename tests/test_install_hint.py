"""Install hints work from where qpcontact came from (issue 33): the index form, and from a
source checkout the editable install of that checkout."""

from __future__ import annotations

from pathlib import Path

from qpcontact.errors import install_hint
from qpcontact.io.tables import EXTRA

ROOT = Path(__file__).resolve().parents[1]


def test_a_source_checkout_is_told_how_to_install_an_extra_from_itself():
    hint = install_hint("table")
    assert hint.startswith("pip install 'qpcontact[table]'")
    assert f"pip install -e '{ROOT}[table]'" in hint  # these tests run from a source checkout
    assert EXTRA == hint
