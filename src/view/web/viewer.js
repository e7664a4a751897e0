// Placeholder: the web helper's viewer.js replaces this.
"use strict";
