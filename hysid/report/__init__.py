"""Reports: every text summary (:mod:`.text`), the Markdown reports with their
publication-quality PNG figures (:mod:`.markdown` for fits and campaigns,
:mod:`.diagnosis`, :mod:`.reproduction`), and strict JSON (:mod:`.jsondoc`)."""
