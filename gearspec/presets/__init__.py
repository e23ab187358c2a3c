"""Built-in gear-train specs (TOML), listed by :func:`gearspec.gears.presets`."""
