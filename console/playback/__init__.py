"""Reading runs back: replay in the console and self-contained HTML exports."""
