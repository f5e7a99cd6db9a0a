"""docs/routes.md's tables are the ones generated from the route files and the car model."""

import re
from pathlib import Path

from biso_cosim.routes import library_table


def test_routes_doc_table_is_in_sync():
    text = (Path(__file__).resolve().parent.parent / "docs" / "routes.md").read_text()
    block = re.search(r"<!-- routes-table:.*?-->\n(.*?)\n<!-- /routes-table -->", text, flags=re.S).group(1)
    assert block.strip() == library_table().strip(), "run: python -c 'from biso_cosim.routes import library_table; print(library_table())'"


def test_routes_doc_limits_table_is_in_sync():
    from biso_cosim.routes import car_limits

    text = (Path(__file__).resolve().parent.parent / "docs" / "routes.md").read_text()
    block = re.search(r"<!-- limits-table:.*?-->\n(.*?)\n<!-- /limits-table -->", text, flags=re.S).group(1)
    assert block.strip() == car_limits().table().strip(), \
        "run: python -c 'from biso_cosim.routes import car_limits; print(car_limits().table())'"
