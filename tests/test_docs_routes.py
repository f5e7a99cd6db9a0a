"""docs/routes.md's library table is the one generated from the route files."""

import re
from pathlib import Path

from biso_cosim.routes import library_table


def test_routes_doc_table_is_in_sync():
    text = (Path(__file__).resolve().parent.parent / "docs" / "routes.md").read_text()
    block = re.search(r"<!-- routes-table:.*?-->\n(.*?)\n<!-- /routes-table -->", text, flags=re.S).group(1)
    assert block.strip() == library_table().strip(), "run: python -c 'from biso_cosim.routes import library_table; print(library_table())'"
