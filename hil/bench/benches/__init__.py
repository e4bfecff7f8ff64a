"""Ready-made device benches (HC11 bridge, AgOpenGPS module, valve) and their measurements."""
