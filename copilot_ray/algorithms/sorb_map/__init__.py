"""SoRB with the map (``algorithm: sorb_map``): SoRB whose graph keeps only wall-free edges."""
