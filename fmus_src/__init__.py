"""Component models of the cnctwin machining-center twin.

Pure physics cores (NC kernel, MCU servo loops, drive axis, cutting load) with
a native batch-capable :class:`~fmus_src.component.Component` interface and
thin pythonfmu wrappers that export each as an FMI 2.0 co-simulation FMU.
"""
