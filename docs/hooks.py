"""MkDocs hook: the settings reference is generated from the settings dataclasses at build time.

A line ``<!-- settings: module.Class section -->`` in a page becomes the table of that
dataclass's fields, defaults and documented meaning (:func:`calib.settings_doc.settings_markdown`).
"""

import importlib
import re

MARKER = re.compile(r"^<!-- settings: ([\w.]+)\.(\w+) (\w+) -->$", re.M)


def on_page_markdown(markdown, page, config, files):
    from calib.settings_doc import settings_markdown

    def table(m):
        cls = getattr(importlib.import_module(m.group(1)), m.group(2))
        return settings_markdown(cls, m.group(3))

    return MARKER.sub(table, markdown)
