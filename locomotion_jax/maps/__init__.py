"""Parameter maps: sweeps over a grid, devices and processes, NetCDF and Zarr storage."""
