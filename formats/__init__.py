"""File formats of a result: what the command line, the service and the client write and draw.

- result_tables: the CIR as the long CSV (cir.csv, result.csv) and as numpy arrays (result.npz)
- plots: the CIR figure, h(t) per reflection order (cir.png, plot.png)
- result_files: a result folder (result.json, links.csv, cir.csv, cir.png, map files)
- maps: coverage maps as arrays (`GridMap`, `MapDecor`), their summary and text table
- map_files: netCDF, MATLAB .mat and pandas tables of maps; heatmap: a map as a PNG

Depends on the wire models (owcsim.schemas) only, never on the engine, the service or the HTTP
client. numpy is the only heavy import at module level; matplotlib, xarray, scipy and pandas (the
`engine` extra) are imported by the functions that need them (optional.need).
"""
