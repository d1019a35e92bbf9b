"""Controller code for a PLC or a microcontroller from a gain table: CSV, IEC 61131-3 Structured Text, PLCopen XML,
C99, through a registry of formats over one intermediate form."""
