"""Planning a measurement: which poses to measure with a tracker (`design`), and which configurations to
record in sockets and on planes (`fixture_design`), and the ISO 9283 test cube (`iso9283`), chosen on the nominal model before anything is
measured. Above the fit (what a pose tells about the coefficients) and the simulator (how poses are
drawn and reached).
"""
