"""Event files and packet codecs (EVT 2.0/2.1/3.0 .raw, .dat, .aedat4, .npy, .csv) and centreline HDF5."""
