"""The bundled demo: a scripted drive made with the project's own simulator, DBC and BLF writer."""
