"""Readers of measured loops: every format ends as a :class:`hysid_model.loops.LoopSet`.

* :mod:`.dataset_dir` ``dataset.toml`` (name, mass, bounds, steady windows,
  sample rate, units, channels) and ``manifest.csv`` (file, frequency);
* :mod:`.csv_series` raw DAQ records ``time_s,displacement_m,force_n``;
* :mod:`.lvm` LabVIEW measurement files (standard text and the headerless
  two-column export of the thesis' rig);
* :mod:`.matfile` the thesis' per-loop ``HexpT``/``HexpB`` ``.mat`` files;
* :mod:`.tidy` the extracted-loops file hysid writes and reads back.

:func:`hysid_model.datasets.load_dataset` picks the reader.
"""
