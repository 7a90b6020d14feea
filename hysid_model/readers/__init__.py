"""Readers of measured loops: every format ends as a :class:`hysid_model.loops.LoopSet`.

* :mod:`.dataset_dir` ``dataset.toml`` (name, mass, bounds, steady windows,
  sample rate, units, channels), ``manifest.csv`` (file, frequency) and the
  confinement of every file to the dataset directory;
* :mod:`.records` which raw records a dataset holds, in which order, at which
  frequency, and which reader reads each;
* :mod:`.channels` time, displacement and force channels and their units,
  one way for every format;
* :mod:`.csv_series` raw DAQ records ``time_s,displacement_m,force_n`` (any
  case, ``;``/tab separators, decimal commas, unit suffixes);
* :mod:`.long_csv` many records in one tidy CSV keyed by a ``record`` column;
* :mod:`.daq` NI TDMS and HDF5 records (optional: ``pip install 'hysid[daq]'``);
* :mod:`.lvm` LabVIEW measurement files (standard text and the headerless
  two-column export of the thesis' rig);
* :mod:`.matfile` the thesis' per-loop ``HexpT``/``HexpB`` ``.mat`` files;
* :mod:`.tidy` the extracted-loops file hysid writes and reads back.

:func:`hysid_model.datasets.load_dataset` picks the reader.
"""
